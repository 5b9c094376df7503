"""The one launcher of the split layout's three processes (no ROS imports).

:func:`launch` starts the micro and macro processes, then the coordinator, which learns their
process ids from :data:`SCALE_PIDS_ENV`; ``conveyor-twin run --split`` and the testing harness
both call it. Each process's output goes to a log file of its own (``log_dir``) or, without one,
to this process's standard error (the coordinator's standard output stays the caller's: it
ends with the summary line, :data:`SUMMARY_PREFIX`). :meth:`SplitProcesses.watch` reports a
process that ends during the run to a :class:`~conveyor_twin.health.Health`, with its exit code
and the last lines of its log.
"""

from collections import deque
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time
from typing import Callable, Deque, Dict, IO, List, Mapping, Optional, Sequence, Tuple

from conveyor_twin.coord.layout import Role
from conveyor_twin.health import Health, process_alive

#: The module each role's process runs (``python -m``).
MODULES = {Role.MICRO: 'conveyor_twin.ros.micro_node', Role.MACRO: 'conveyor_twin.ros.macro_node',
           Role.COORDINATOR: 'conveyor_twin.ros.split'}
#: Environment variable through which the launcher tells the coordinator the process ids of the
#: scale nodes: ``micro_simulator=PID,macro_simulator=PID``.
SCALE_PIDS_ENV = 'CONVEYOR_TWIN_SCALE_PIDS'
#: Set (to ``1``) by ``conveyor-twin run --split`` for its scale processes: they ignore SIGINT
#: and stop on SIGTERM, which the run sends once the coordinator has stopped; so a Ctrl-C in
#: the terminal (SIGINT to every process) never leaves the coordinator waiting for a scale
#: process that is gone.
IGNORE_SIGINT_ENV = 'CONVEYOR_TWIN_IGNORE_SIGINT'
#: The coordinator prints its closing figures as one line of JSON after this prefix.
SUMMARY_PREFIX = 'conveyor_twin summary: '
LOG_TAIL = 2000  # characters of a log file quoted in a failure [1]
LOG_TAIL_LINES = 20  # lines of a relayed log kept for a failure report [1]
CHILD_POLL = 0.1  # s between two checks that the processes live
COORDINATOR_GRACE = 30.0  # s the coordinator may take to stop after a scale process died
STOP_TIMEOUT = 10.0  # s the scale processes may take to stop after SIGTERM

#: Starts a process: ``start(argv, env=extra environment, **Popen arguments)``.
Starter = Callable[..., subprocess.Popen]


def ros_args(cell_file: str, seed: Optional[int], mode: str, duration: float,
             namespace: Optional[str], markers_rate: float, *, foxglove: str = '',
             scenario: str = '') -> List[str]:
    """Return the ``--ros-args`` of the three processes of a split run (durations [s], rates
    [Hz]; ``foxglove``: ``[HOST:]PORT`` of the coordinator's Foxglove view, empty: none;
    ``scenario``: the fault scenario file the coordinator arms, empty: none)."""
    args = ['--ros-args', '-p', f'mode:={mode}', '-p', f'duration:={float(duration)}',
            '-p', f'markers_rate:={float(markers_rate)}']
    if cell_file:  # rcl cannot parse an empty override; empty is the default anyway
        args += ['-p', f'cell_file:={cell_file}']
    if seed is not None:
        args += ['-p', f'seed:={seed}']
    if foxglove:  # quoted: rcl would read a bare port as an integer
        args += ['-p', f'foxglove:="{foxglove}"']
    if scenario:
        args += ['-p', f'scenario:={scenario}']
    if namespace:
        args += ['-r', f'__ns:={namespace}']
    return args


def scale_pids_from_env(environ: Mapping[str, str] = os.environ) -> Dict[Role, int]:
    """Return the scale processes' ids by role from :data:`SCALE_PIDS_ENV` (empty if unset)."""
    roles = {role.node_name: role for role in (Role.MICRO, Role.MACRO)}
    out: Dict[Role, int] = {}
    for item in filter(None, environ.get(SCALE_PIDS_ENV, '').split(',')):
        name, _, pid = item.partition('=')
        if name in roles and pid.isdigit():
            out[roles[name]] = int(pid)
    return out


def check_scale_processes(health: Health, pids: Mapping[Role, int]) -> None:
    """Report every scale process of ``pids`` that has ended to ``health`` (once each)."""
    for role, pid in pids.items():
        if not process_alive(pid):
            health.report(f'{Role(role).node_name} process',
                          message=f'the process (pid {pid}) ended during the run')


def log_tail(path: Path, size: int = LOG_TAIL) -> str:
    """Return the last ``size`` characters of a log file ('' if there is none)."""
    try:
        return path.read_text(errors='replace')[-size:]
    except OSError:
        return ''


def _popen(argv: Sequence[str], *, env: Mapping[str, str], **kwargs) -> subprocess.Popen:
    return subprocess.Popen(list(argv), env=dict(os.environ, **env), **kwargs)


class SplitChild:
    """One process of the split layout and its log.

    :param log: its log file; None: its output is relayed to our standard error (the
        coordinator's standard output is left to the caller: ``proc.stdout``).
    """

    def __init__(self, role: Role, argv: List[str], env: Mapping[str, str], start: Starter,
                 log: Optional[Path]) -> None:
        self.role = role
        self.name = role.node_name
        self.log = log
        self._tail: Deque[str] = deque(maxlen=LOG_TAIL_LINES)
        self._relay_thread: Optional[threading.Thread] = None
        if log is not None:
            with open(log, 'w') as out:
                self.proc = start(argv, env=env, stdout=out, stderr=out)
            return
        coordinator = role is Role.COORDINATOR
        self.proc = start(argv, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE if coordinator else subprocess.STDOUT,
                          text=True, errors='replace')
        stream = self.proc.stderr if coordinator else self.proc.stdout
        self._relay_thread = threading.Thread(target=self._relay, args=(stream,),
                                              name=f'{self.name}_log', daemon=True)
        self._relay_thread.start()

    def _relay(self, stream: IO[str]) -> None:
        for line in stream:
            self._tail.append(line)
            sys.stderr.write(line)
        sys.stderr.flush()

    def tail(self) -> str:
        """Return the last lines the process wrote ('' if none)."""
        if self.log is not None:
            return log_tail(self.log)
        if self._relay_thread is not None and self.proc.poll() is not None:
            self._relay_thread.join(2.0)  # the rest of what it wrote
        return ''.join(self._tail)

    def report(self, health: Health, when: str) -> None:
        """Report this process's end to ``health`` with its exit code and log tail."""
        code = self.proc.poll()
        where = f' ({self.log})' if self.log is not None else ''
        tail = self.tail() or '(it wrote nothing)\n'
        health.report(f'{self.name} process', message=f'exited with code {code} {when}',
                      detail=f'last lines of its log{where}:\n{tail}')


class SplitProcesses:
    """The started processes of a split run: the two scale processes and the coordinator."""

    def __init__(self, scales: Tuple[SplitChild, ...], coordinator: SplitChild) -> None:
        self.scales = scales
        self.coordinator = coordinator
        self.children = scales + (coordinator,)
        self._done = threading.Event()
        self._watcher: Optional[threading.Thread] = None

    def dead(self) -> List[SplitChild]:
        """Return the processes that have ended."""
        return [c for c in self.children if c.proc.poll() is not None]

    def logs(self) -> str:
        """Return the last lines each process wrote."""
        return '\n'.join(f'--- {c.log.name if c.log else c.name}\n{c.tail()}'
                         for c in self.children)

    def watch(self, health: Health) -> None:
        """Report a scale process that ends before :meth:`end_watch` to ``health`` (once,
        with its exit code and log tail); give the coordinator :data:`COORDINATOR_GRACE` to
        stop by itself, then interrupt it. The watcher's own failure is reported too."""
        self._watcher = health.thread('split process watcher', self._watch, health)
        self._watcher.start()

    def _watch(self, health: Health) -> None:
        failed_at = None
        while not self._done.wait(CHILD_POLL):
            for child in self.scales:
                if child.proc.poll() is not None and not self._done.is_set():
                    child.report(health, 'during the run')
                    if failed_at is None:
                        failed_at = time.monotonic()
            if (failed_at is not None and time.monotonic() - failed_at > COORDINATOR_GRACE
                    and self.coordinator.proc.poll() is None):
                self.coordinator.proc.send_signal(signal.SIGINT)
                failed_at = float('inf')

    def end_watch(self) -> None:
        """Stop watching (the coordinator ended: the scale processes are stopped now)."""
        self._done.set()
        if self._watcher is not None:
            self._watcher.join(5.0)

    def stop_scales(self, timeout: float = STOP_TIMEOUT) -> None:
        """Send SIGTERM to the scale processes still running; kill those that do not end
        within ``timeout`` [s]."""
        for child in self.scales:
            if child.proc.poll() is None:
                child.proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for child in self.scales:
            try:
                child.proc.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                child.proc.kill()
                child.proc.wait()


def launch(process_args: List[str], *, start: Starter = _popen,
           log_dir: Optional[Path] = None, ignore_sigint: bool = False) -> SplitProcesses:
    """Start the micro and macro processes, then the coordinator (told their process ids).

    :param process_args: the processes' arguments (:func:`ros_args`).
    :param start: starts one process, ``start(argv, env=extra environment, **Popen
        arguments)`` (default: :class:`subprocess.Popen` with this environment plus ``env``;
        the testing harness passes its ``RosProcesses.start``).
    :param log_dir: where each process writes its output (``<module>.log``); None: relayed to
        our standard error (the coordinator's standard output is the caller's to read).
    :param ignore_sigint: the scale processes ignore SIGINT (:data:`IGNORE_SIGINT_ENV`): stop
        them with :meth:`SplitProcesses.stop_scales` after the coordinator.
    """
    def child(role: Role, env: Dict[str, str]) -> SplitChild:
        module = MODULES[role]
        log = log_dir / f'{module.rsplit(".", 1)[1]}.log' if log_dir is not None else None
        return SplitChild(role, [sys.executable, '-m', module] + process_args, env, start, log)

    scale_env = {IGNORE_SIGINT_ENV: '1'} if ignore_sigint else {}
    scales = tuple(child(role, scale_env) for role in (Role.MICRO, Role.MACRO))
    pids = ','.join(f'{c.name}={c.proc.pid}' for c in scales)
    return SplitProcesses(scales, child(Role.COORDINATOR, {SCALE_PIDS_ENV: pids}))
