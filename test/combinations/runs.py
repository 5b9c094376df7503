"""One run of a cell shared by the checks of every output: a lockstep twin watched through
ROS (the testing harness) and a Foxglove client at once, and a recording of the same cell, seed,
commands and faults made by ``conveyor-twin run``."""

from dataclasses import dataclass, field
import json
from pathlib import Path
import socket
import subprocess
import sys
from typing import Dict, List, Optional

from conveyor_twin.coord.warmup import warm_up
from conveyor_twin.record import reader
from conveyor_twin.testing import LockstepTwin, ros_subprocess_env
from conveyor_twin.viz.foxglove_view import DEFAULT_STREAM_RATE
from conveyor_twin.wire import cdr

from . import matrix
from .foxglove_client import FoxgloveClient, Received

SEED = 7
#: Harness topics compared with the other outputs (``diagnostics`` carries wall-clock times).
HARNESS_TOPICS = ('parts', 'density', 'light_barriers', 'light_barrier_edges', 'belt_states',
                  'actuator_states', '/clock', 'faults', 'command_status')
CLI_TIMEOUT = 600.0  # s: a generous bound for a child process under load
#: Longest wait of the harness for one answer of the twin [s]: generous, for a loaded machine.
TWIN_TIMEOUT = 180.0
#: Most steps a split run takes until the coordinator's view has the scale streams.
WARM_UP_STEPS = 100


@dataclass
class CellRun:
    """What one run of a cell produced, by output."""

    case: matrix.CellCase
    scenario: Path
    step_ns: int
    steps: int
    #: harness (ROS) messages by contract topic name, in arrival order
    ros: Dict[str, List[bytes]] = field(default_factory=dict)
    #: Foxglove messages, in arrival order
    foxglove: List[Received] = field(default_factory=list)
    #: frames forwarded whole to Foxglove: one in ``every``
    foxglove_every: int = 1
    foxglove_channels: Dict[str, dict] = field(default_factory=dict)
    foxglove_statuses: List[dict] = field(default_factory=list)
    #: why the Foxglove client did not receive everything ('' when it did)
    foxglove_error: str = ''
    #: the step from which the client has every per-step stream (0: from the start)
    foxglove_from: int = 0

    def silenced(self) -> Dict[str, set]:
        """Steps each stream was silenced by a ``stream_outage`` (from the ROS fault states)."""
        return matrix.silenced_steps(self.ros['faults'], self.step_ns, self.steps)


def lockstep_run(case: matrix.CellCase, scenario: Path, *, layout: str = 'composed',
                 foxglove: bool = True, steps: int = matrix.STEPS) -> CellRun:
    """Run ``case`` in lockstep with ``scenario``, the belt command of the matrix, and (if
    ``foxglove``) a Foxglove client subscribed to everything.

    Composed, the client subscribes before the first step. Split, the coordinator takes the
    scale streams from ROS only once a client watches, so the run steps one step at a time
    until every per-step stream has reached the client (:attr:`CellRun.foxglove_from`).
    """
    run = CellRun(case, scenario, 0, steps)
    # numba compiles the cell's kernels on their first call (minutes of CPU on a clean
    # checkout, cached on disk for the child processes): here, not within a service call
    warm_up(case.cell, SEED)
    port = None
    if foxglove:
        port = '127.0.0.1:0' if layout == 'composed' else f'127.0.0.1:{free_port()}'
    with LockstepTwin(str(case.path), seed=SEED, layout=layout, scenario=str(scenario),
                      foxglove=port, timeout=TWIN_TIMEOUT) as twin:
        run.step_ns = round(twin.step_s * 1e9)
        client: Optional[FoxgloveClient] = None
        try:
            if port is not None and layout == 'composed':
                view = twin.foxglove
                client = FoxgloveClient(view.port)
                client.wait(lambda: view.active, 'the view sees the client subscribed')
                run.foxglove_every = view.every
            elif port is not None:
                client = FoxgloveClient(int(port.rsplit(':', 1)[1]))
                run.foxglove_every = max(1, round(1.0 / (DEFAULT_STREAM_RATE * twin.step_s)))
                _warm_up(run, twin, client)
            twin.step(matrix.COMMAND_STEP - 1 - twin.step_index)
            belt, speed = matrix.belt_command(case)
            twin.set_belt(belt, speed)
            twin.step(steps - matrix.COMMAND_STEP + 1)
            run.ros = {topic: list(twin.messages(topic)) for topic in HARNESS_TOPICS}
            if client is not None:
                try:
                    _wait_for_foxglove(run, client, twin.cell)
                except AssertionError as exc:  # the Foxglove check reports it; the others run
                    run.foxglove_error = str(exc)
                run.foxglove = list(client.received)
                run.foxglove_channels = dict(client.channels)
                run.foxglove_statuses = list(client.statuses)
        finally:
            if client is not None:
                client.close()
    return run


def free_port() -> int:
    """Return a TCP port of 127.0.0.1 that was free a moment ago."""
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def _own_streams(cell) -> List[str]:
    return [t for t in matrix.PER_STEP if t != '/clock'] + (
        ['/density'] if matrix.macro_zones(cell) else [])


def _warm_up(run: CellRun, twin: LockstepTwin, client: FoxgloveClient) -> None:
    """Step one step at a time until every per-step stream reached the client."""
    streams = _own_streams(twin.cell)
    for _ in range(WARM_UP_STEPS):
        twin.step(1)
        try:
            client.wait(lambda: all(client.messages(t) for t in streams),
                        'every per-step stream reaches the client', timeout=5.0)
        except AssertionError:
            continue
        run.foxglove_from = twin.step_index
        return
    run.foxglove_error = (f'split: not every per-step stream of {streams} reached the '
                          f'Foxglove client within {WARM_UP_STEPS} steps')
    run.foxglove_from = twin.step_index


def forwarded_steps(run: CellRun) -> List[int]:
    """Steps whose frame the composed view forwards whole (the first after the client
    subscribed, then one in ``every``)."""
    return list(range(1, run.steps + 1, run.foxglove_every))


def _wait_for_foxglove(run: CellRun, client: FoxgloveClient, cell) -> None:
    """Wait until the client has every message of the run it should get: each per-step stream
    up to the run's last ``every`` steps, every edge and fault state since it watches, a scene
    and a density grid per macro zone as recent."""
    last = (run.steps - run.foxglove_every + 1) * run.step_ns
    silenced = run.silenced()
    ends_silent = {t for t, steps in silenced.items() if run.steps in steps}
    wanted = [t for t in _own_streams(cell) + ['/clock'] if t not in ends_silent]
    since = run.foxglove_from * run.step_ns
    zones = matrix.macro_zones(cell)

    def count(name: str) -> int:
        return len([d for d in run.ros[name] if cdr.stamp_of(d) > since])

    def recent(topic: str) -> bool:
        return any(m.log_time >= last for m in client.messages(topic))

    def arrived() -> bool:
        return (all(recent(t) for t in wanted)
                and len(client.messages('/light_barrier_edges')) >= count('light_barrier_edges')
                and len(client.messages('/faults')) >= count('faults')
                and recent('/scene') and all(recent(f'/scene/density/{z}') for z in zones))

    client.wait(arrived, f'the Foxglove client receives every stream up to {last} ns, every '
                         f'edge and fault state, a scene and the density grids of {zones}')


def record(case: matrix.CellCase, scenario: Path, path: Path, *,
           steps: int = matrix.STEPS) -> dict:
    """Record ``case`` with ``conveyor-twin run --record`` (fast mode, the run's seed, scenario
    and belt command); return the run's JSON summary."""
    belt, speed = matrix.belt_command(case)
    duration = steps * case.cell.settings.step
    args = [sys.executable, '-m', 'conveyor_twin.cli', 'run', '--cell', str(case.path),
            '--seed', str(SEED), '--mode', 'fast', '--duration', repr(duration),
            '--scenario', str(scenario), '--record', str(path), '--quiet', '--json',
            '--command', f'{matrix.COMMAND_STEP}:belt:{belt}={speed}']
    done = subprocess.run(args, env=ros_subprocess_env(), capture_output=True, text=True,
                          timeout=CLI_TIMEOUT, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, f'{" ".join(args)}: exit {done.returncode}\n{done.stderr}'
    return json.loads(done.stdout)


def recorded(path: Path) -> Dict[str, List[bytes]]:
    """Return a recording's messages by topic, in log-time order."""
    out: Dict[str, List[bytes]] = {}
    for m in reader.read_messages(str(path)):
        out.setdefault(m.topic, []).append(m.data)
    return out


def cli(args: List[str], *, cwd: Optional[Path] = None) -> subprocess.CompletedProcess:
    """Run ``conveyor-twin ARGS`` in a child process; return what it did (text)."""
    return subprocess.run([sys.executable, '-m', 'conveyor_twin.cli', *args],
                          env=ros_subprocess_env(), capture_output=True, text=True,
                          timeout=CLI_TIMEOUT, stdin=subprocess.DEVNULL, cwd=cwd)
