"""Attach a :class:`~conveyor_twin.viz.foxglove_view.FoxgloveView` to a twin.

Composed layout (:func:`attach`): the view is a sink of the twin's per-step frames (every
stream's CDR bytes, built once per step, as the ROS publishers send them). Split layout
(:func:`attach_split`, in the ``scale_coordinator`` process): the coordinator's own frames, and
the scale nodes' streams taken from ROS by raw subscriptions (:class:`ScaleStreams`). Either way
the view is fed only while a Foxglove client is subscribed to something, so with no client the
twin pays nothing. Commands published by Foxglove clients go through the coordinator's command
book like ``belt_command``/``actuator_command`` (rejections are counted in ``diagnostics`` and
logged); ``step``, ``reset`` and ``spawn_parts`` are served by the coordinator's own service
callbacks (requests and responses in CDR). The address is the nodes' read-only parameter
``foxglove`` (``conveyor-twin run --foxglove``, ``LockstepTwin(foxglove=...)``). The view's
threads report their failures to the twin's ``health``.

A plant (:func:`attach_plant`, ``conveyor-twin plant --foxglove``): one
:class:`~conveyor_twin.viz.foxglove_plant.PlantView` of every cell, fed by raw subscriptions to
each cell's streams under its namespace (:class:`PlantStreams`).
"""

import itertools
import threading
from typing import Any, Callable, Dict, List, Optional

from conveyor_twin_msgs.srv import Reset, SpawnParts, Step
from rclpy.serialization import deserialize_message, serialize_message

from conveyor_twin import contract
from conveyor_twin.coord.commands import CommandKind, CommandRejected, SEQUENCE_MAX
from conveyor_twin.ros.endpoints import create_subscription
from conveyor_twin.record.topics import resolve
from conveyor_twin.viz.foxglove_view import (DEFAULT_BACKLOG, DEFAULT_SCENE_RATE,
                                             DEFAULT_STREAM_RATE, FoxgloveView,
                                             parse_address, ServiceSpec)
from conveyor_twin.wire import schemas
from conveyor_twin.wire.cdr import stamp_of

_TIME = (f"\n{schemas.SEPARATOR}\nMSG: builtin_interfaces/Time\n"
         + schemas.MSG_TEXTS['builtin_interfaces/msg/Time'])
#: ``sender`` of the commands Foxglove clients publish (numbered in ``sequence``).
FOXGLOVE_SENDER = 'foxglove'
#: (name, type, request ros2msg text, response ros2msg text) of the services (msg_defs/srv).
SERVICE_TEXTS = (
    (contract.STEP.name, contract.STEP.type_name, 'uint32 steps\n',
     'uint64 step\nbuiltin_interfaces/Time stamp\n' + _TIME),
    (contract.RESET.name, contract.RESET.type_name, 'string cell_file\nuint64 seed\n',
     'bool success\nstring message\n'),
    (contract.SPAWN_PARTS.name, contract.SPAWN_PARTS.type_name,
     'string part_type\nfloat64[] x\nfloat64[] y\nfloat64[] yaw\n',
     'bool success\nstring message\nuint32[] id\n'),
)


def _cdr_service(srv_type: Any, callback: Callable) -> Callable[[bytes], bytes]:
    def handle(payload: bytes) -> bytes:
        request = deserialize_message(payload, srv_type.Request)
        return serialize_message(callback(request, srv_type.Response()))
    return handle


def attach(composed: Any, address: str, *, stream_rate: float = DEFAULT_STREAM_RATE,
           scene_rate: float = DEFAULT_SCENE_RATE,
           backlog: int = DEFAULT_BACKLOG) -> FoxgloveView:
    """Start a Foxglove server for a composed twin (``ComposedTwin``); return the view.

    :param address: ``[HOST:]PORT`` (host 127.0.0.1 by default; port 0: any free port).
    :param stream_rate: rate of the per-step streams sent to clients [Hz].
    :param scene_rate: rate of the 3D scene [Hz].
    :param backlog: messages queued at most, in the twin and per client [1].
    :raises FoxgloveError: if the address is invalid, the host unknown or the port taken.
    """
    output = composed.output
    view = _view(composed.coordinator, composed.twin, composed.cell, stream_rate=stream_rate,
                 scene_rate=scene_rate, backlog=backlog)
    view.on_active = lambda active: (output.subscribe if active else output.unsubscribe)(view)
    _serve(view, composed.coordinator, address)
    return view


def attach_split(coordinator: Any, address: str, *, stream_rate: float = DEFAULT_STREAM_RATE,
                 scene_rate: float = DEFAULT_SCENE_RATE,
                 backlog: int = DEFAULT_BACKLOG) -> FoxgloveView:
    """Start a Foxglove server in the split layout's coordinator process; return the view.

    The coordinator's streams come from its frames; the scale nodes' streams (parts, light
    barriers, edges, density, markers) from ROS, subscribed only while a client watches.
    Parameters as :func:`attach`.
    """
    twin = coordinator.twin
    view = _view(coordinator, twin, twin.cell, stream_rate=stream_rate, scene_rate=scene_rate,
                 backlog=backlog)
    scale = ScaleStreams(coordinator, view)
    output = coordinator.output

    def on_active(active: bool) -> None:
        (output.subscribe if active else output.unsubscribe)(view)
        scale.set_active(active)

    view.on_active = on_active
    _serve(view, coordinator, address)
    return view


class ScaleStreams:
    """Raw subscriptions of the coordinator to the scale nodes' streams, feeding a view.

    Created when the first client subscribes, destroyed when the last one goes; each message
    goes to :meth:`FoxgloveView.sink` (which thins the per-step streams to its rate) with the
    stamp of its header, or the latest step's time for ``markers``.
    """

    TOPICS = tuple(t for t in contract.STREAMS if t.producer is not contract.Producer.COORDINATOR)

    def __init__(self, node: Any, view: FoxgloveView) -> None:
        self.node = node
        self.view = view
        self._subscriptions: List[Any] = []
        self._lock = threading.Lock()

    def set_active(self, active: bool) -> None:
        """Subscribe (True) or unsubscribe (False) the scale streams."""
        with self._lock:
            if active and not self._subscriptions:
                self._subscriptions = [create_subscription(self.node, topic,
                                                           self._callback(topic), raw=True)
                                       for topic in self.TOPICS]
            elif not active:
                for subscription in self._subscriptions:
                    self.node.destroy_subscription(subscription)
                self._subscriptions = []

    def _callback(self, topic: contract.Topic) -> Callable[[bytes], None]:
        name = resolve(topic.name, self.node.get_namespace())
        sink = self.view.sink
        if topic.stamp is contract.Stamp.HEADER:
            return lambda data: sink(name, stamp_of(data), data)
        output = self.node.output
        return lambda data: sink(name, output.frame.time_ns, data)


def _view(coordinator: Any, twin: Any, cell: Any, **rates: Any) -> FoxgloveView:
    """Build the view of a twin: its streams, commands through the command book, services."""
    namespace = coordinator.get_namespace()
    streams: Dict[str, str] = {resolve(topic.name, namespace): topic.type_name
                               for topic in contract.STREAMS}

    numbers = itertools.count(1)  # the view's commands, in order (sequence of sender foxglove)

    def on_command(kind: str, name: str, value: float) -> Optional[str]:
        sequence = next(numbers) & SEQUENCE_MAX
        try:
            if kind == CommandKind.BELT:
                twin.commands.submit_belt(name, value, FOXGLOVE_SENDER, sequence)
            else:
                twin.commands.submit_actuator(name, value, FOXGLOVE_SENDER, sequence)
        except CommandRejected as exc:
            coordinator.report_rejected(exc)
            return str(exc)
        return None

    callbacks = {contract.STEP.name: (Step, coordinator._on_step),
                 contract.RESET.name: (Reset, coordinator._on_reset),
                 contract.SPAWN_PARTS.name: (SpawnParts, coordinator._on_spawn)}
    services = tuple(ServiceSpec(name, type_name, request, response,
                                 _cdr_service(*callbacks[name]))
                     for name, type_name, request, response in SERVICE_TEXTS)
    view = FoxgloveView(cell, streams=streams, namespace=namespace,
                        step_s=cell.settings.step, on_command=on_command,
                        services=services, health=twin.health, **rates)
    view.on_invalid = lambda reason: _count_invalid(twin, coordinator, reason)
    return view


def _serve(view: FoxgloveView, coordinator: Any, address: str) -> None:
    """Start the view's server at ``address``, count it in diagnostics and log where it is."""
    host, port = parse_address(address)
    view.start(host, port)
    coordinator.add_counters(lambda: {f'foxglove_{k}': v for k, v in view.counters().items()})
    coordinator.get_logger().info(f'Foxglove view at ws://{host}:{view.port} (Foxglove: Open '
                                  'connection, Foxglove WebSocket)')


def _count_invalid(twin: Any, coordinator: Any, reason: str) -> None:
    """Count a client message that is no valid command (undecodable, other topic) like a
    rejected command: in ``diagnostics`` and the log."""
    coordinator.report_rejected(twin.commands.reject('foxglove_invalid', reason))


def attach_plant(node: Any, plant: Any, address: str, *, health: Any = None,
                 stream_rate: float = DEFAULT_STREAM_RATE,
                 scene_rate: float = DEFAULT_SCENE_RATE) -> Any:
    """Start one Foxglove server showing every cell of ``plant``; return the view.

    ``node`` (spun by the caller) subscribes to every cell's streams under the cell's
    namespace while a client watches (best effort: a view that falls behind loses messages,
    never slows a cell), whether the cells run in other processes or in this one.

    :raises FoxgloveError: if the address is invalid, the host unknown or the port taken.
    """
    from conveyor_twin.viz.foxglove_plant import PlantView
    view = PlantView(plant, stream_rate=stream_rate, scene_rate=scene_rate, health=health)
    streams = PlantStreams(node, view)
    view.on_active = streams.set_active
    host, port = parse_address(address)
    view.start(host, port)
    return view


class PlantStreams:
    """Raw subscriptions of one node to every stream a :class:`PlantView` serves, created
    when the first client subscribes and destroyed when the last one goes."""

    def __init__(self, node: Any, view: Any) -> None:
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        self.node = node
        self.view = view
        self.qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                              reliability=ReliabilityPolicy.BEST_EFFORT)
        self._types = {t.name: t.type_name for t in contract.STREAMS}
        self._subscriptions: List[Any] = []
        self._lock = threading.Lock()

    def set_active(self, active: bool) -> None:
        """Subscribe (True) or unsubscribe (False) every cell's streams."""
        from conveyor_twin.ros.endpoints import message_class
        with self._lock:
            if active and not self._subscriptions:
                self._subscriptions = [
                    self.node.create_subscription(message_class(self._types[rel]), topic,
                                                  self._callback(topic), self.qos, raw=True)
                    for topic, (_, rel, _) in self.view.streams.items()]
            elif not active:
                for subscription in self._subscriptions:
                    self.node.destroy_subscription(subscription)
                self._subscriptions = []

    def _callback(self, topic: str) -> Callable[[bytes], None]:
        sink = self.view.sink
        return lambda data: sink(topic, stamp_of(data), data)
