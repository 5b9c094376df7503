"""Frames handed to sinks on a thread of their own, in order, none dropped (realtime publishing).

In realtime the step's work and the delay before it starts must fit in one period. Publishing
a frame's streams (~0.1 ms for 1000 parts on five streams) is work the step does not need to
wait for: :class:`FrameRelay` takes the frame's references on the stepping thread (a few us),
and a thread of its own calls the sinks while the stepping thread sleeps to its next deadline.
Unlike :class:`~conveyor_twin.output.queued.QueuedSink` (a slow viewer: frames dropped when its
queue is full), the relay never drops a frame: a full queue makes the step wait (counted in
:attr:`FrameRelay.waits`), so a stream may come late but never loses a message.
"""

from collections import deque
import threading
from typing import Callable, Deque, Optional, Sequence

from conveyor_twin.health import Health
from conveyor_twin.output.frame import Frame, FrameSink

#: Default bound of the relay's queue [frames] (1 s at 1 kHz).
DEFAULT_CAPACITY = 1000
#: How long the worker waits for a frame before looking at ``close`` again [s].
_IDLE_WAIT = 0.05


class FrameRelay:
    """Call ``sinks[i].on_frame`` for every frame, in order, on a worker thread.

    :param sinks: the frame sinks to relay to (e.g. a node's stream publishers).
    :param capacity: frames queued at most; a step that finds the queue full waits for room.
    :param name: the worker thread's name, and the name of its failure in ``health``.
    :param health: where the worker's exception is reported (once, with its traceback: the
        twin's diagnostics turn ERROR and a run ends non-zero); after it, frames are counted
        in :attr:`dropped`, not queued.
    :param on_start: called first on the worker thread (e.g. to set its realtime priority).
    :param after: called on the worker thread with each frame after the sinks (work that
        belongs off the step, e.g. the 1 Hz diagnostics).
    """

    def __init__(self, sinks: Sequence[FrameSink], *, capacity: int = DEFAULT_CAPACITY,
                 name: str = 'conveyor_twin_publisher', health: Optional[Health] = None,
                 on_start: Optional[Callable[[], None]] = None,
                 after: Optional[Callable[[Frame], None]] = None) -> None:
        if capacity < 1:
            raise ValueError(f'capacity {capacity}: expected >= 1')
        self.sinks = tuple(sinks)
        self.capacity = capacity
        self.name = name
        self.health = health if health is not None else Health()
        #: Frames relayed to every sink.
        self.delivered = 0
        #: Steps that found the queue full and waited for room.
        self.waits = 0
        #: Frames handed to :meth:`on_frame`.
        self.offered = 0
        #: True while :meth:`on_frame` waits for room (the caller's step is blocked in it).
        self.step_waiting = False
        self.error: Optional[BaseException] = None
        self._on_start = on_start
        self._after = after
        self._queue: Deque[Frame] = deque()
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def on_frame(self, frame: Frame) -> None:
        """Queue the frame's references (the bytes are immutable); wait if the queue is full.

        After a failure of the worker, or after :meth:`close`, the frame is counted in
        :attr:`dropped` instead.
        """
        self.offered += 1
        if self.error is not None or self._closed:
            return
        queue = self._queue
        if len(queue) >= self.capacity:
            self.waits += 1
            self.step_waiting = True
            try:
                with self._cond:
                    while len(queue) >= self.capacity and self.error is None:
                        self._cond.wait(_IDLE_WAIT)
            finally:
                self.step_waiting = False
        queue.append(frame.copy())
        if len(queue) == 1:
            with self._cond:
                self._cond.notify_all()

    def _run(self) -> None:
        try:
            if self._on_start is not None:
                self._on_start()
            queue, cond, sinks, after = self._queue, self._cond, self.sinks, self._after
            while True:
                if not queue:
                    with cond:
                        cond.notify_all()  # flush() waits for an empty queue
                        while not queue and not self._closed:
                            cond.wait(_IDLE_WAIT)
                        if not queue:
                            return
                frame = queue[0]
                for sink in sinks:
                    sink.on_frame(frame)
                if after is not None:
                    after(frame)
                queue.popleft()  # after publishing: flush() sees it until it is out
                self.delivered += 1
                if len(queue) == self.capacity - 1:
                    with cond:
                        cond.notify_all()  # a step waiting for room
        except BaseException as exc:  # noqa: B902 - reported once, never swallowed
            self.health.report(self.name, exc)
            with self._cond:
                self.error = exc
                self._queue.clear()
                self._cond.notify_all()

    def flush(self, timeout: float = 5.0) -> bool:
        """Wait until every queued frame is relayed [s]; return False on timeout or failure."""
        with self._cond:
            return self._cond.wait_for(
                lambda: self.error is not None or not self._queue,
                timeout) and self.error is None

    def close(self, timeout: float = 5.0) -> None:
        """Relay what is queued, then stop the worker [s to wait for each]."""
        self.flush(timeout)
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join(timeout)

    @property
    def dropped(self) -> int:
        """Frames not relayed to every sink because the worker failed or was closed."""
        return self.offered - self.delivered - len(self._queue)

    @property
    def pending(self) -> int:
        """Frames queued and not yet relayed."""
        return len(self._queue)
