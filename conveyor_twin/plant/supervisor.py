"""The cell processes of a plant run by one parent: started, watched, restarted on request.

:class:`CellProcesses` starts one process per cell (``conveyor-twin plant PLANT --cell NAME``)
and watches them. A process that ends before its cell reported ``done`` (killed, crashed, an
exit status other than 0) died: the death is reported once to the :class:`~conveyor_twin.
health.Health` given (naming the cell, its exit status and its last line of output) and the
last lines of its output are printed; the cell is then started again under a new run id if it
has restarts left (``restarts`` per cell), else it stays dead and the other cells run on.

Each process' output (standard output and error together) is read by a thread of its own:
its last JSON line is the cell's summary, every other line is echoed to standard error with
the cell's name in front and the last :data:`TAIL_LINES` are kept for the report of a death.
No ROS imports.
"""

from collections import deque
import json
import os
import signal
import subprocess
import sys
import threading
from typing import Callable, Deque, Dict, List, Optional, Sequence, TextIO

from conveyor_twin.health import Health

#: Lines of a cell process' output kept for the report of its death.
TAIL_LINES = 12


def describe_status(code: int) -> str:
    """Return an exit status as a person reads it (``-9``: ``-9 (killed by SIGKILL)``)."""
    if code < 0:
        try:
            return f'{code} (killed by {signal.Signals(-code).name})'
        except ValueError:
            return f'{code} (killed by signal {-code})'
    return str(code)


def end_process(p: subprocess.Popen, reader: Optional[threading.Thread],
                timeout: float) -> int:
    """Ask a child started in a process group of its own to end (SIGINT), kill the group after
    ``timeout`` [s], wait for its output ``reader`` thread; return the exit status."""
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
    try:
        p.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.wait()
    if reader is not None:
        reader.join(5.0)
    return p.returncode


class CellProcess:
    """One cell's process and what it wrote.

    :param name: the cell. :param command: the command line of a run of it.
    :param echo: where its output lines go, with ``[name]`` in front (None: nowhere).
    :param health: where a failure of its output reader is reported.
    """

    def __init__(self, name: str, command: Sequence[str], *, echo: Optional[TextIO],
                 health: Health) -> None:
        self.name = name
        self.command = list(command)
        self.tail: Deque[str] = deque(maxlen=TAIL_LINES)
        #: The last JSON line the process printed (its summary), if any.
        self.summary: Optional[dict] = None
        #: Runs started (1 for the first run).
        self.runs = 0
        self._echo = echo
        self._health = health
        self._lock = threading.Lock()
        self.popen: Optional[subprocess.Popen] = None
        self._reader: Optional[threading.Thread] = None

    def start(self) -> None:
        """Start a run of the cell (a new process; the cell takes a new run id)."""
        self.runs += 1
        self.popen = subprocess.Popen(self.command, stdout=subprocess.PIPE,
                                      stderr=subprocess.STDOUT, text=True, errors='replace',
                                      start_new_session=True)
        self._reader = self._health.thread(f'output reader of cell {self.name!r}', self._read,
                                           self.popen.stdout)
        self._reader.start()

    def _read(self, stream: TextIO) -> None:
        for line in stream:
            line = line.rstrip('\n')
            if line.startswith('{'):
                try:
                    self.summary = json.loads(line)
                    continue
                except ValueError:
                    pass
            with self._lock:
                self.tail.append(line)
            if self._echo is not None:
                self._echo.write(f'[{self.name}] {line}\n')
                self._echo.flush()

    def poll(self) -> Optional[int]:
        """The exit status of the current run, None while it runs."""
        return self.popen.poll() if self.popen is not None else None

    def last_lines(self) -> List[str]:
        """The last lines of output (waits a moment for the reader after the process ended)."""
        if self._reader is not None and self.poll() is not None:
            self._reader.join(2.0)
        with self._lock:
            return list(self.tail)

    def stop(self, timeout: float) -> Optional[int]:
        """Ask the run to end (SIGINT), kill its process group after ``timeout`` [s]; return
        its exit status."""
        if self.popen is None:
            return None
        return end_process(self.popen, self._reader, timeout)


class CellProcesses:
    """Every cell of a plant in a process of its own, supervised.

    :param commands: the command line of each cell, by name (in plant order).
    :param health: where deaths (and failures of the output readers) are reported.
    :param restarts: how often a cell that died is started again (0: never) [runs].
    :param echo: where the cells' output lines and the reports of deaths go.
    """

    def __init__(self, commands: Dict[str, Sequence[str]], *, health: Health,
                 restarts: int = 0, echo: Optional[TextIO] = None) -> None:
        if restarts < 0:
            raise ValueError(f'restarts: got {restarts}; expected an integer >= 0')
        self.health = health
        self.restart_limit = int(restarts)
        self._out = echo if echo is not None else sys.stderr
        self.cells: Dict[str, CellProcess] = {
            name: CellProcess(name, cmd, echo=self._out, health=health)
            for name, cmd in commands.items()}
        #: Cells that died with no restart left (they stay dead).
        self.dead: List[str] = []
        #: Deaths so far: (cell, run number, exit status).
        self.deaths: List[tuple] = []

    def start(self) -> None:
        """Start every cell."""
        for c in self.cells.values():
            c.start()

    def restarts(self) -> Dict[str, int]:
        """How often each cell was started again [runs]."""
        return {name: c.runs - 1 for name, c in self.cells.items()}

    def watch(self, done: Callable[[str], bool]) -> List[str]:
        """Look at every running cell once: report a cell whose process ended before it was
        ``done`` (or with a status other than 0), and start it again if it has restarts left.

        :param done: True if the cell's current run reported it completed its last step.
        :return: the cells that died in this call.
        """
        died = []
        for name, c in self.cells.items():
            if name in self.dead:
                continue
            code = c.poll()
            if code is None or (code == 0 and done(name)):
                continue
            died.append(name)
            self.deaths.append((name, c.runs, code))
            lines = c.last_lines()
            last = lines[-1] if lines else '(no output)'
            self.health.report(f'cell {name!r} process (run {c.runs})',
                               message=f'exit status {describe_status(code)}; last output: '
                               f'{last}')
            self._out.write(f'conveyor-twin plant: cell {name!r} died (exit status '
                            f'{describe_status(code)}); its last output:\n'
                            + ''.join(f'  | {x}\n' for x in lines or ['(none)']))
            if c.runs - 1 < self.restart_limit:
                self._out.write(f'conveyor-twin plant: starting cell {name!r} again (restart '
                                f'{c.runs} of {self.restart_limit})\n')
                c.start()
            else:
                self.dead.append(name)
                self._out.write(f'conveyor-twin plant: cell {name!r} stays dead; the other '
                                'cells run on\n')
            self._out.flush()
        return died

    def stop(self, timeout: float) -> List[dict]:
        """Stop every cell (SIGINT, then SIGKILL after ``timeout`` [s]); return their
        summaries (the cells that printed one)."""
        for c in self.cells.values():
            if c.poll() is None and c.popen is not None:
                c.popen.send_signal(signal.SIGINT)
        for c in self.cells.values():
            c.stop(timeout)
        return [c.summary for c in self.cells.values() if c.summary is not None]
