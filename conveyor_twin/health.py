"""Failures of the twin's background threads and child processes: reported once, never silent.

Every thread or process that works beside the stepping loop (a recorder writer, the Foxglove
view, a queued sink, the markers thread, a plant link, a controller process, a scale node of
the split layout) reports its end by exception to the :class:`Health` of its twin. The first
report of each name is printed once with its traceback; after it the twin's diagnostics carry
an ERROR status naming the failure (:meth:`Health.status`), a run ends non-zero and the testing
harness fails the test (:meth:`Health.raise_if_failed`).

No ROS imports: the cores, the sinks and the nodes all use it.
"""

from dataclasses import dataclass
import os
import sys
import threading
import time
import traceback
from typing import Callable, List, Optional, Tuple

#: Exit code of a run that ended because a background thread or process failed.
EXIT_BACKGROUND_FAILURE = 3


@dataclass(frozen=True)
class Failure:
    """One failed thread or process.

    :param name: what failed, as a person reads it (``'foxglove view'``, ``'recorder writer'``).
    :param error: the exception's one-line description (``repr``), or the process' exit status.
    :param traceback: the formatted traceback (for a process: what it left, e.g. the last
        lines of its log, or '').
    :param wall_time: when it was reported [s, ``time.time()``].
    """

    name: str
    error: str
    traceback: str
    wall_time: float

    def describe(self) -> str:
        """One line: ``name: error``."""
        return f'{self.name}: {self.error}'


class BackgroundFailure(RuntimeError):
    """Raised where a caller must learn that a background thread or process of the twin died."""

    def __init__(self, failures: Tuple[Failure, ...]) -> None:
        self.failures = failures
        lines = '\n'.join(f'- {f.describe()}\n{_indent(f.traceback)}' for f in failures)
        super().__init__(f'{len(failures)} background failure(s) of the twin:\n{lines}')


class Health:
    """The failures of one twin's background threads and processes.

    Thread-safe: any thread may :meth:`report`. Each name is reported once (later reports of
    the same name are counted, not printed again). Listeners are called once per new failure,
    on the reporting thread, and must not block.

    :param printer: where the one report per failure goes (default: standard error).
    """

    def __init__(self, printer: Optional[Callable[[str], None]] = None) -> None:
        self._lock = threading.Lock()
        self._failures: List[Failure] = []
        self._repeats = 0
        self._printer = printer or _print_stderr
        #: False until the first failure: a plain attribute, cheap enough to read every step.
        self.failed = False
        #: Set at the first failure (wait on it instead of polling).
        self.event = threading.Event()
        #: Called with each new :class:`Failure` (e.g. to stop the run, log through ROS).
        self.listeners: List[Callable[[Failure], None]] = []

    def report(self, name: str, exc: Optional[BaseException] = None, *,
               message: str = '', detail: str = '') -> Failure:
        """Record that ``name`` failed, with its exception (or a ``message`` without one).

        :param detail: printed with the report in place of a traceback when there is no
            exception (e.g. the last lines of a dead process's log).
        :return: the failure recorded for ``name`` (the first one, if it was already reported).
        """
        if exc is not None:
            error = repr(exc)
            trace = ''.join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        else:
            error = message or 'failed'
            trace = detail
        with self._lock:
            for known in self._failures:
                if known.name == name:
                    self._repeats += 1
                    return known
            failure = Failure(name=name, error=error, traceback=trace, wall_time=time.time())
            self._failures.append(failure)
            self.failed = True
            listeners = list(self.listeners)
        self._printer(f'conveyor_twin: {name} failed: {error}\n{trace}'.rstrip() + '\n')
        for listener in listeners:
            try:
                listener(failure)
            except Exception as listener_exc:  # a listener must not hide the failure
                self._printer(f'conveyor_twin: a failure listener raised {listener_exc!r}\n')
        self.event.set()  # after the report is out and the listeners ran
        return failure

    @property
    def failures(self) -> Tuple[Failure, ...]:
        """Every failure so far, in the order reported."""
        with self._lock:
            return tuple(self._failures)

    @property
    def ok(self) -> bool:
        """True while nothing has failed."""
        with self._lock:
            return not self._failures

    def status(self) -> Tuple[bool, str]:
        """(failed, message) for a diagnostics status: the names and errors of every failure."""
        failures = self.failures
        if not failures:
            return False, 'every background thread and process alive'
        return True, 'failed: ' + '; '.join(f.describe() for f in failures)

    def summary(self) -> List[dict]:
        """Every failure as ``{'name', 'error'}`` (for a run's JSON summary)."""
        return [{'name': f.name, 'error': f.error} for f in self.failures]

    def raise_if_failed(self) -> None:
        """Raise :class:`BackgroundFailure` if anything failed."""
        failures = self.failures
        if failures:
            raise BackgroundFailure(failures)

    def guard(self, name: str, target: Callable[..., object]) -> Callable[..., None]:
        """Wrap a thread target so that an exception it raises is reported as ``name``."""
        def guarded(*args, **kwargs) -> None:
            try:
                target(*args, **kwargs)
            except BaseException as exc:  # reported once, never swallowed
                self.report(name, exc)
        return guarded

    def thread(self, name: str, target: Callable[..., object], *args,
               daemon: bool = True) -> threading.Thread:
        """Return an unstarted thread (named ``name``) whose exception is reported as ``name``."""
        return threading.Thread(target=self.guard(name, target), args=args,
                                name=name.replace(' ', '_'), daemon=daemon)


def process_alive(pid: int) -> bool:
    """Return True if process ``pid`` runs (a zombie, ended but not yet reaped, does not)."""
    try:
        with open(f'/proc/{pid}/stat', 'rb') as f:
            stat = f.read()
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    # the state follows the command name in parentheses (which may contain anything)
    state = stat[stat.rfind(b')') + 2:stat.rfind(b')') + 3]
    return state not in (b'Z', b'X', b'x')


def _print_stderr(text: str) -> None:
    sys.stderr.write(text)
    sys.stderr.flush()


def _indent(text: str) -> str:
    return ''.join('    ' + line + '\n' for line in text.splitlines())
