"""What the harness watches besides the streams: the twin's background threads and processes,
and the controller processes a test started (their output, their deaths, their pacing).

:meth:`Supervisor.check` raises :class:`~conveyor_twin.health.BackgroundFailure` once anything
failed: a background thread of the composed twin (its :class:`~conveyor_twin.health.Health`),
a split process that ended (by node name, with its exit code and the tail of its log), or a
controller process that ended with a non-zero exit code or by a signal. The harness checks it
before every call that drives the twin and while it waits.
"""

from pathlib import Path
import subprocess
from typing import List, Mapping, Optional, Sequence

from conveyor_twin import contract
from conveyor_twin.health import BackgroundFailure, Health
from conveyor_twin.split.launch import log_tail
from conveyor_twin.testing._layout import RunningLayout
from conveyor_twin.testing.driver import command_origin, Driver
from conveyor_twin.testing.pacing import AckListener
from conveyor_twin.testing.processes import RosProcesses
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.serialization import deserialize_message


class Controller:
    """A controller process a test started.

    :param index: its number in the order started
    :param args: its command line
    :param process: the process
    :param log: the file its output goes to
    :param pace: the node whose acknowledgements pace the harness ('' : not paced)
    """

    def __init__(self, index: int, args: Sequence[str], process: subprocess.Popen, log: Path,
                 pace: str) -> None:
        self.index = index
        self.args = list(args)
        self.process = process
        self.log = log
        self.pace = pace

    @property
    def name(self) -> str:
        """How a failure names it."""
        return f'controller process {self.index} ({" ".join(self.args)[-80:]})'


class Supervisor:
    """The harness's watch over the twin's health and the controller processes.

    :param running: the started twin
    :param log_dir: the twin's folder of logs (split processes, controllers)
    :param processes: where controller processes are started (the twin's domain)
    """

    def __init__(self, running: RunningLayout, log_dir: Path, processes: RosProcesses) -> None:
        self.running = running
        self.log_dir = log_dir
        self.processes = processes
        #: Failures of the split processes and the controller processes.
        self.health = Health()
        self.controllers: List[Controller] = []
        self._acks: Optional[AckListener] = None
        self._answered: dict = {}  # paced node -> the last of its commands seen answered
        self._stopping = False

    # -- failures ------------------------------------------------------------------------
    def _healths(self) -> List[Health]:
        composed = self.running.composed
        twin = getattr(composed, 'twin', None)
        return [self.health] + ([twin.health] if twin is not None else [])

    def check(self) -> None:
        """Raise :class:`BackgroundFailure` naming every failure so far (none: return)."""
        if self._stopping:
            return
        for name, code, log in self.running.dead():
            self.health.report(f'{name} process', message=f'exited with code {code}',
                               detail=f'last lines of its log ({log}):\n{log_tail(log)}')
        for c in self.controllers:
            code = c.process.poll()
            if code is not None and code != 0:
                self.health.report(c.name, message=f'exited with code {code}',
                                   detail=f'last lines of its output ({c.log}):\n'
                                          f'{log_tail(c.log)}')
        failures = tuple(f for h in self._healths() for f in h.failures)
        if failures:
            raise BackgroundFailure(failures)

    def failed(self) -> bool:
        """True if anything failed (without raising)."""
        try:
            self.check()
        except BackgroundFailure:
            return True
        return False

    def stop(self) -> None:
        """Stop watching (the harness is closing: processes end on purpose)."""
        self._stopping = True

    # -- controllers ---------------------------------------------------------------------
    def start(self, args: Sequence[str], env: Optional[Mapping[str, str]], pace: str,
              driver: Driver) -> Controller:
        """Start a controller process; with ``pace``, pace the harness by its node."""
        index = len(self.controllers)
        path = self.log_dir / f'controller_{index}.log'
        with open(path, 'w') as log:
            process = self.processes.start(list(args), env=env, stdout=log,
                                           stderr=subprocess.STDOUT)
        controller = Controller(index, args, process, path, pace)
        self.controllers.append(controller)
        if pace and self._acks is None:
            self._acks = AckListener(driver.probe)
        return controller

    def output(self, index: int) -> str:
        """Return what controller ``index`` printed so far."""
        path = self.log_dir / f'controller_{index}.log'
        return path.read_text(errors='replace') if path.exists() else ''

    def report(self) -> str:
        """Every controller's state and the tail of its output, for a failure message."""
        lines = []
        for c in self.controllers:
            code = c.process.poll()
            state = 'running' if code is None else f'exited with {code}'
            lines.append(f'\n--- controller {c.index} ({state}):\n{log_tail(c.log)}')
        return ''.join(lines)

    def paced(self) -> List[str]:
        """The names of the nodes that pace the harness."""
        return [c.pace for c in self.controllers if c.pace]

    def wait_paced(self, driver: Driver, stamp_ns: int) -> None:
        """Wait until every paced node acknowledged ``stamp_ns`` and the twin answered the
        last command each sent before (nothing to do without paced controllers)."""
        names = self.paced()
        if not names or self._acks is None:
            return
        acks = self._acks
        for name in names:
            driver.wait(lambda n=name: acks.stamp_ns(n) >= stamp_ns,
                        lambda n=name: f'paced controller {n!r} to acknowledge stamp '
                                       f'{stamp_ns} ns on lockstep_ack (last: '
                                       f'{acks.stamp_ns(n)} ns)')
            sender, sequence = acks.last_command(name)
            if sequence > self._answered.get(name, 0):
                driver.wait(lambda s=sender, q=sequence: _answered(driver, s, q),
                            f'answer of the twin to command {sequence} of {sender!r}')
                self._answered[name] = sequence
        driver.settle_commands()

    def forget_acks(self) -> None:
        """Forget the acknowledgements received (after a reset: stamps start again at 0)."""
        if self._acks is not None:
            self._acks.acks.clear()


def _answered(driver: Driver, sender: str, sequence: int) -> bool:
    """True once ``command_status`` holds the answer to (sender, sequence) or a later one."""
    for data in reversed(driver.probe.received[contract.COMMAND_STATUS.name]):
        who, number = command_origin(deserialize_message(data, DiagnosticStatus))
        if who == sender and number >= sequence:
            return True
    return False


def keep_dir_note(path: Path) -> str:
    """The sentence an error ends with when the twin's logs are kept."""
    return f'\n(the twin\'s logs are kept in {path})'
