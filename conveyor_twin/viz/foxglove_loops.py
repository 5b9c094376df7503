"""What every Foxglove view of the twin shares: its queue, its two threads and its clients.

A view is fed on the twin's side (cheap, never blocking) and serves clients on two threads of
its own: the publisher hands the queued messages to the SDK's channels every
``PUBLISH_PERIOD``, the scene thread draws the scene at ``scene_rate``. Both sleep while no
client watches (they wake at the first subscription or at :meth:`ViewLoops.stop`), so a view
nobody watches never competes for the interpreter lock. An exception in either thread is
reported to the view's :class:`~conveyor_twin.health.Health`.

No rclpy and no SDK import at module level: the SDK is imported when a server starts.
"""

from collections import deque
import threading
import time
from typing import Callable, Deque, Dict, List, Optional, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.contract import ACTUATOR_STATES, LIGHT_BARRIERS, PARTS
from conveyor_twin.health import Health
from conveyor_twin.output.markers import CellMarkers
from conveyor_twin.wire import cdr, schemas

#: Publisher thread period [s].
PUBLISH_PERIOD = 0.01
#: While no client watches, the view's threads sleep until one subscribes (or the view stops);
#: they look again after this long at most [s].
IDLE_WAIT = 1.0


def ros_channel(foxglove, context, topic: str, type_name: str):
    """A channel of ``cdr`` messages of a contract type (``ros2msg`` schema)."""
    schema = foxglove.Schema(name=type_name, encoding='ros2msg',
                             data=schemas.full_text(type_name).encode())
    return foxglove.Channel(topic, schema=schema, message_encoding='cdr', context=context)


def cell_scene(markers: CellMarkers, cell: Cell,
               latest: Dict[str, Tuple[int, bytes]]) -> Optional[Tuple[int, bytes]]:
    """(stamp [ns], MarkerArray CDR) of a cell's scene from the latest ``parts``,
    ``light_barriers`` and ``actuator_states`` messages; None before the first ``parts``."""
    parts = latest.get(PARTS.name)
    if parts is None:
        return None
    stamp_ns, data = parts
    p = cdr.decode_part_states(data)
    blocked = np.zeros(len(cell.light_barriers), bool)
    barriers = latest.get(LIGHT_BARRIERS.name)
    if barriers is not None:
        blocked = cdr.decode_light_barrier_states(barriers[1])[4]
    position = np.array([a.initial_position for a in cell.actuators])
    actuators = latest.get(ACTUATOR_STATES.name)
    if actuators is not None:
        from conveyor_twin.wire.decoders import decode_actuator_states
        position = decode_actuator_states(actuators[1]).actual
    return stamp_ns, markers.build(stamp_ns, p.part_type, p.x, p.y, blocked, position)


class ViewLoops:
    """The queue, threads and client subscriptions of a Foxglove view (a base class).

    A subclass creates its channels, starts its server (:attr:`server`, :attr:`proxy`), then
    calls :meth:`_start_threads`; it implements :meth:`build_scene`.

    :param scene_rate: rate of the scenes [Hz].
    :param backlog: queued messages at most [1].
    :param health: where the threads report an exception (default: a health of its own,
        printed on standard error).
    """

    def __init__(self, *, scene_rate: float, backlog: int,
                 health: Optional[Health] = None) -> None:
        self.health = health if health is not None else Health()
        self.scene_period = 1.0 / scene_rate
        self.backlog = backlog
        self._queue: Deque[Tuple[str, int, bytes]] = deque()
        self.active = False          # a client is subscribed to something
        #: Called with True when the first client subscription arrives and with False when
        #: the last one goes (the ROS side starts and stops feeding the view).
        self.on_active: Callable[[bool], None] = lambda active: None
        self.dropped = 0             # messages dropped from the full queue
        self.sent = 0                # messages handed to the SDK
        self.scenes = 0              # scenes built
        self._subscriptions: Dict[Tuple[int, int], str] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._watched = threading.Event()  # set while a client is subscribed, or to stop
        self._threads: List[threading.Thread] = []
        self.server = None
        self.proxy = None
        self.port = 0
        self.channels: Dict[str, object] = {}

    def _enqueue(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Queue a message for the publisher thread; drop the oldest when the queue is full."""
        if len(self._queue) >= self.backlog:
            self._queue.popleft()
            self.dropped += 1
        self._queue.append((topic, stamp_ns, data))

    def _start_threads(self, publisher_name: str, scene_name: str) -> None:
        """Start the publisher and scene threads, reporting as the names given."""
        for target, name in ((self._publish_loop, publisher_name),
                             (self._scene_loop, scene_name)):
            thread = self.health.thread(name, target)
            thread.start()
            self._threads.append(thread)

    def stop(self) -> None:
        """Stop the threads and the server (clients are disconnected)."""
        self._stop.set()
        self._watched.set()
        for thread in self._threads:
            thread.join(2.0)
        if self.proxy is not None:
            self.proxy.stop()
            self.proxy = None
        if self.server is not None:
            self.server.stop()
            self.server = None

    def build_scene(self) -> None:
        """Log the scene of the latest state (scene thread)."""
        raise NotImplementedError

    def _on_first_subscription(self) -> None:
        """Called (under the lock) when a client subscribes to an unwatched view."""

    # -- threads ---------------------------------------------------------------------------
    def _publish_loop(self) -> None:
        queue = self._queue
        while not self._stop.is_set():
            if not self.active and not queue:
                self._watched.wait(IDLE_WAIT)
                continue
            if self._stop.wait(PUBLISH_PERIOD):
                break
            while queue:
                topic, stamp_ns, data = queue.popleft()
                self.channels[topic].log(data, log_time=stamp_ns)
                self.sent += 1

    def _scene_loop(self) -> None:
        next_time = time.monotonic()
        while not self._stop.is_set():
            if not self.active:
                self._watched.wait(IDLE_WAIT)
                next_time = time.monotonic()
                continue
            next_time += self.scene_period
            delay = next_time - time.monotonic()
            if delay < 0.0:
                next_time = time.monotonic()
            elif self._stop.wait(delay):
                break
            if self.active:
                self.build_scene()

    # -- clients ---------------------------------------------------------------------------
    def _subscribed(self, key: Tuple[int, int], topic: str, on: bool) -> None:
        with self._lock:
            if on:
                self._subscriptions[key] = topic
            else:
                self._subscriptions.pop(key, None)
            active = bool(self._subscriptions)
            changed = active != self.active
            if active and changed:
                self._queue.clear()
                self._on_first_subscription()
            self.active = active
            if active:
                self._watched.set()
            elif not self._stop.is_set():
                self._watched.clear()
            if changed:  # under the lock: the ROS side sees the changes in order
                self.on_active(active)
