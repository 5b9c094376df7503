"""A sink for slow consumers: frames go through a bounded queue to a thread of their own.

The stepping thread only copies the frame's references (the bytes are immutable) into a
bounded deque; a full queue drops the frame and counts it, so a consumer that cannot keep up
(a viewer, a test harness doing assertions) never blocks or slows the step.
"""

from collections import deque
import threading
from typing import Callable, Deque, Optional, Tuple

from conveyor_twin.contract import Topic
from conveyor_twin.health import Health
from conveyor_twin.output.frame import Frame

#: Default bound of the queue [frames or messages].
DEFAULT_QUEUE_SIZE = 1000


class QueuedSink:
    """Hand copies of the frames (and off-step messages) to ``consumer`` on a worker thread.

    :param on_frame: called with each queued :class:`Frame` (a copy it may keep).
    :param on_message: called with (topic, stamp [ns], bytes) of each off-step message
        (``markers``); None: such messages are ignored.
    :param queue_size: bound of the queue; beyond it frames are dropped and counted in
        :attr:`dropped`.
    :param name: name of the worker thread, and of the sink in a failure report.
    :param health: where the consumer's exception is reported (the twin's
        :attr:`~conveyor_twin.coord.twin.Twin.health`, e.g. ``output.health``); None: a health
        of the sink's own, which still prints the report once. After an exception the sink
        stops consuming, keeps it in :attr:`error` and drops (and counts) later frames.
    """

    def __init__(self, on_frame: Callable[[Frame], None], *,
                 on_message: Optional[Callable[[Topic, int, bytes], None]] = None,
                 queue_size: int = DEFAULT_QUEUE_SIZE, name: str = 'conveyor_twin_sink',
                 health: Optional[Health] = None) -> None:
        if queue_size < 1:
            raise ValueError(f'queue_size {queue_size}: expected >= 1')
        self._consume_frame = on_frame
        self._consume_message = on_message
        self.queue_size = queue_size
        self.dropped = 0
        self.delivered = 0
        self._queue: Deque[Tuple[Optional[Frame], Tuple[Topic, int, bytes]]] = deque()
        self._wake = threading.Condition()
        self._closed = False
        self.error: Optional[BaseException] = None
        self.name = name
        self.health = health if health is not None else Health()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def on_frame(self, frame: Frame) -> None:
        """Queue a copy of the frame, or drop it if the queue is full (never blocks)."""
        self._put((frame.copy(), ()))

    def on_message(self, topic: Topic, stamp_ns: int, data: bytes) -> None:
        """Queue an off-step message, or drop it if the queue is full (never blocks)."""
        if self._consume_message is not None:
            self._put((None, (topic, stamp_ns, data)))

    def _put(self, item) -> None:
        if len(self._queue) >= self.queue_size or self._closed:
            self.dropped += 1
            return
        self._queue.append(item)
        if len(self._queue) == 1:
            with self._wake:
                self._wake.notify()

    def _run(self) -> None:
        while True:
            with self._wake:
                while not self._queue and not self._closed:
                    self._wake.wait(0.05)
            if not self._queue and self._closed:
                return
            frame, message = self._queue.popleft()
            try:
                if frame is not None:
                    self._consume_frame(frame)
                else:
                    self._consume_message(*message)
                self.delivered += 1
            except BaseException as exc:  # noqa: B902 - reported, never the step's
                self.error = exc
                self._closed = True
                self._queue.clear()
                self.health.report(self.name, exc)
                return

    def close(self, timeout: float = 5.0) -> None:
        """Deliver what is queued, then stop the worker thread [s to wait]."""
        self._closed = True
        with self._wake:
            self._wake.notify()
        self._thread.join(timeout)
