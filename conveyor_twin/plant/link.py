"""The two ends of a transfer link and the batches they exchange (no ROS imports).

The exit end (:class:`LinkExit`, in the upstream cell) takes parts out of the cell, numbers
them (``seq``, from 0, per link), sends them in :class:`Departures` batches and holds every part
until the entry end reports it inserted: what the downstream cell never took stays in the
link, whatever happens to that cell. The entry end (:class:`LinkEntry`, in the downstream cell)
releases a part at its leave step plus the delay, in order; if the entry is occupied the part
waits (the backlog) and so do the ones behind it. It reports insertions and how far its cell
has run in :class:`Acceptances` batches.

Both batch kinds carry ``through``: the step the sending cell has completed, which is what the
other end needs to know how far it may run (:mod:`conveyor_twin.plant.sync`). A batch is what
travels between processes (:mod:`conveyor_twin.ros.plant_cell_node`) or is handed over directly
(:mod:`conveyor_twin.plant.runner`): the same data either way.
"""

from bisect import bisect_right
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Deque, List, NamedTuple, Optional, Set, Tuple

from conveyor_twin.plant.model import Link


class Transit(NamedTuple):
    """One part in a link: pose and velocity relative to the link's exit frame.

    :param seq: number of the part in the link (0, 1, ...).
    :param step: step in which it left the upstream cell.
    :param id: its id in the upstream cell. :param origin: its id where it entered the plant.
    :param part_type: type index in the upstream cell.
    :param x: [m]. :param y: [m] lateral offset. :param yaw: [rad]. :param vx: [m/s].
    :param vy: [m/s]. :param wz: [rad/s].
    """

    seq: int
    step: int
    id: int
    origin: int
    part_type: int
    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    wz: float


@dataclass
class Departures:
    """Exit to entry: parts that left (``seq`` consecutive from ``first_seq``), the exit cell's
    completed step, its oldest part not yet reported inserted (``held_from``) and the id of
    the exit cell's run (``seq`` and steps count from 0 in every run)."""

    link: str
    through: int
    first_seq: int
    held_from: int
    parts: List[Transit] = field(default_factory=list)
    run: int = 0


@dataclass
class Acceptances:
    """Entry to exit: parts inserted (``seq`` and the step of insertion, in order), the entry
    cell's completed step, the id of the entry cell's current run (a restarted cell has
    another), and whether the entry still waits for the exit's oldest held part
    (``starting``: the exit then sends every part it holds). ``exit_run``: the run of the
    exit cell whose parts the entry takes (None: none yet); ``seq`` numbers its parts, and
    ``through`` and ``step`` count in its steps. ``final``: the entry cell's run has completed
    its last step, and this batch and the ones before it report every part it inserted."""

    link: str
    through: int
    run: int
    seq: List[int] = field(default_factory=list)
    step: List[int] = field(default_factory=list)
    starting: bool = False
    exit_run: Optional[int] = None
    final: bool = False


class LinkExit:
    """The upstream end of a link: takes, numbers, sends and holds parts.

    :param link: the link.
    :param run: id of this run of the exit cell (a restarted cell has another).
    """

    def __init__(self, link: Link, run: int = 0) -> None:
        self.link = link
        self.run = run
        self.delay = link.delay_steps
        self.capacity = link.capacity
        #: Steps completed by the cell here and by the entry's cell.
        self.through = 0
        self.peer_through = 0
        self.sent = 0
        self.held: Deque[Transit] = deque()
        self._outgoing: List[Transit] = []
        self._first_unsent = 0
        self.peer_run: Optional[int] = None
        # insertion steps reported by the entry's current run, and how many earlier runs took
        self._accepted_steps: List[int] = []
        self._accepted_before = 0
        self.accepted = 0
        #: Parts re-sent to a restarted entry cell.
        self.resent = 0
        #: The entry's current run has completed its last step and reported every insertion.
        self.peer_final = False

    @property
    def in_link(self) -> int:
        """Parts sent and not reported inserted [parts]."""
        return self.sent - self.accepted

    def inserted_until(self, step: int) -> int:
        """Parts the entry reported inserted in steps <= ``step``."""
        return self._accepted_before + bisect_right(self._accepted_steps, step)

    def room(self, step: int) -> int:
        """Parts the exit may take in ``step`` (requires ``peer_through >= step - delay``):
        the capacity less the parts sent before ``step`` and not inserted by ``step - delay``.
        A very large number without a capacity."""
        if not self.capacity:
            return 1 << 62
        return max(0, self.capacity - (self.sent - self.inserted_until(step - self.delay)))

    def add(self, part: Transit) -> None:
        """Append a part that left in this step (its ``seq`` must be :attr:`sent`)."""
        assert part.seq == self.sent, (part.seq, self.sent)
        self.sent += 1
        self.held.append(part)
        self._outgoing.append(part)

    def batch(self) -> Departures:
        """Return the parts not sent yet with the current ``through``; mark them sent."""
        first = self._first_unsent
        parts, self._outgoing = self._outgoing, []
        self._first_unsent = first + len(parts)
        held_from = self.held[0].seq if self.held else self.sent
        return Departures(self.link.name, self.through, first, held_from, parts, self.run)

    def _send_held(self) -> None:
        """Make the next batch start at the oldest held part."""
        self._outgoing = list(self.held)
        self._first_unsent = self.held[0].seq if self.held else self.sent

    def receive(self, batch: Acceptances) -> None:
        """Take the entry's report: drop the parts it inserted, learn its progress.

        A report from another run of the entry cell (restarted) makes every held part go
        out again (the new run starts empty and takes them from the oldest on); so does a
        report of an entry still ``starting`` (its first batch was lost before the two ends
        had found each other). A report about another run of this exit cell (an earlier one,
        before the entry heard of this run) says nothing about this run's parts or steps.
        """
        if batch.exit_run is not None and batch.exit_run != self.run:
            return
        if self.peer_run is not None and batch.run != self.peer_run:
            self._accepted_before += len(self._accepted_steps)
            self._accepted_steps = []
            self.resent += len(self.held)
            self.peer_through = batch.through
            self._send_held()
        elif batch.starting and self._first_unsent != (self.held[0].seq if self.held
                                                       else self.sent):
            self._send_held()
        self.peer_run = batch.run
        self.peer_final = batch.final
        for seq, step in zip(batch.seq, batch.step):
            if not self.held or self.held[0].seq != seq:
                continue  # a duplicate report
            self.held.popleft()
            self._accepted_steps.append(step)
            self.accepted += 1
        self.peer_through = max(self.peer_through, batch.through)


class LinkEntry:
    """The downstream end of a link: receives parts in order and inserts them when due.

    The entry follows one run of the exit cell at a time. When a batch of another run comes
    (the exit cell restarted: it numbers parts and counts steps from 0 again), the parts of the
    earlier run that wait in the queue are dropped (they were lost with that run; counted in
    :attr:`dropped`), and the new run's steps count from this cell's step at that moment
    (:attr:`offset`): its step ``k`` is this cell's step ``offset + k``. Batches of an earlier
    run that come later are ignored.

    :param link: the link.
    :param run: id of this run of the entry cell (changes when the cell restarts).
    """

    def __init__(self, link: Link, run: int = 0) -> None:
        self.link = link
        self.delay = link.delay_steps
        self.run = run
        self.through = 0
        #: Steps the exit cell has completed, in this cell's steps.
        self.peer_through = 0
        self.queue: Deque[Transit] = deque()
        self.expected: Optional[int] = None
        #: Parts inserted (from every run of the exit cell) [parts].
        self.inserted = 0
        #: The run of the exit cell whose parts the entry takes (None: none heard yet).
        self.peer_run: Optional[int] = None
        #: This cell's step where the exit cell's current run began [steps] (0 for the run
        #: heard first).
        self.offset = 0
        #: Of :attr:`inserted`, parts of earlier runs of the exit cell [parts].
        self.earlier = 0
        #: Parts of earlier runs of the exit cell received and never inserted [parts].
        self.dropped = 0
        self._ended_runs: Set[int] = set()
        self._seq: List[int] = []
        self._step: List[int] = []
        #: This cell's run has completed its last step (reported as ``final``).
        self.finished = False

    def _follow(self, run: int) -> None:
        """Drop what is left of the exit cell's current run and follow ``run``."""
        if self.peer_run is not None:
            self._ended_runs.add(self.peer_run)
            self.dropped += len(self.queue)
            self.queue.clear()
            self.earlier = self.inserted
            self.offset = self.through
            self.peer_through = self.through
            self.expected = None
            self._seq, self._step = [], []   # their exit run is gone: nobody to tell
        self.peer_run = run

    def receive(self, batch: Departures) -> None:
        """Take a batch of departures: parts in sequence are queued, repeats ignored; a fresh
        entry starts with the batch that begins at the exit's oldest held part (until then it
        learns nothing from the exit, not even how far it ran: it may not step). A batch of
        another run of the exit cell starts following that run (see the class docstring).

        :raises ValueError: if a part is missing between two batches of one run.
        """
        if batch.run in self._ended_runs:
            return
        if batch.run != self.peer_run:
            self._follow(batch.run)
        if self.expected is None:
            if batch.first_seq != batch.held_from:
                return
            self.expected = batch.first_seq
        for part in batch.parts:
            if part.seq < self.expected:
                continue
            if part.seq > self.expected:
                raise ValueError(f'link {self.link.name!r}: part {part.seq} arrived, '
                                 f'{self.expected} expected (a batch was lost)')
            self.queue.append(part)
            self.expected += 1
        self.peer_through = max(self.peer_through, batch.through + self.offset)

    def insert(self, step: int, place: Callable[[Transit], int]) -> Tuple[int, int]:
        """Insert the parts due at ``step`` in order until one does not fit.

        :param place: places a part in the cell; returns its new id or 0 if refused.
        :return: (parts inserted, parts due but waiting).
        """
        done = 0
        queue = self.queue
        due = step - self.delay - self.offset   # the latest leave step due now
        while queue and queue[0].step <= due:
            if not place(queue[0]):
                break
            part = queue.popleft()
            self._seq.append(part.seq)
            self._step.append(step)
            done += 1
        self.inserted += done
        return done, self.waiting(step)

    def waiting(self, step: int) -> int:
        """Parts due by ``step`` and not inserted: the backlog [parts]."""
        n = 0
        due = step - self.delay - self.offset
        for part in self.queue:
            if part.step > due:
                break
            n += 1
        return n

    def batch(self) -> Acceptances:
        """Return the insertions not reported yet with the current ``through`` (both in the
        steps of the exit cell's current run)."""
        off = self.offset
        out = Acceptances(self.link.name, self.through - off, self.run, self._seq,
                          [s - off for s in self._step] if off else self._step,
                          starting=self.expected is None, exit_run=self.peer_run,
                          final=self.finished)
        self._seq, self._step = [], []
        return out
