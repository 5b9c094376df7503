"""Attach a :class:`~conveyor_twin.viz.foxglove_view.FoxgloveView` to a composed twin.

``conveyor-twin run --foxglove [HOST:]PORT`` and tests call :func:`attach` before the twin
starts. The view is a sink of the twin's per-step frames (every stream's CDR bytes, built once
per step, as the ROS publishers send them); commands published by Foxglove clients go through the
coordinator's command book like ``belt_command``/``actuator_command`` (rejections are counted in
``diagnostics`` and logged); ``step``, ``reset`` and ``spawn_parts`` are served by the
coordinator's own service callbacks (requests and responses in CDR). The address is the
coordinator's read-only parameter ``foxglove``.
"""

from typing import Any, Callable, Dict, Optional

from conveyor_twin_msgs.srv import Reset, SpawnParts, Step
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.serialization import deserialize_message, serialize_message

from conveyor_twin import contract
from conveyor_twin.coord.commands import BELT, CommandRejected
from conveyor_twin.output.frame import Frame
from conveyor_twin.record.topics import resolve
from conveyor_twin.viz.foxglove_view import (DEFAULT_BACKLOG, DEFAULT_SCENE_RATE,
                                             DEFAULT_STREAM_RATE, FoxgloveView,
                                             parse_address, ServiceSpec)
from conveyor_twin.wire import schemas

_TIME = (f"\n{schemas.SEPARATOR}\nMSG: builtin_interfaces/Time\n"
         + schemas.MSG_TEXTS['builtin_interfaces/msg/Time'])
#: (name, type, request ros2msg text, response ros2msg text) of the services (msg_defs/srv).
SERVICE_TEXTS = (
    ('step', 'conveyor_twin_msgs/srv/Step', 'uint32 steps\n',
     'uint64 step\nbuiltin_interfaces/Time stamp\n' + _TIME),
    ('reset', 'conveyor_twin_msgs/srv/Reset', 'string cell_file\nuint64 seed\n',
     'bool success\nstring message\n'),
    ('spawn_parts', 'conveyor_twin_msgs/srv/SpawnParts',
     'string part_type\nfloat64[] x\nfloat64[] y\nfloat64[] yaw\n',
     'bool success\nstring message\nuint32[] id\n'),
)


def _cdr_service(srv_type: Any, callback: Callable) -> Callable[[bytes], bytes]:
    def handle(payload: bytes) -> bytes:
        request = deserialize_message(payload, srv_type.Request)
        return serialize_message(callback(request, srv_type.Response()))
    return handle


class _FrameFeed:
    """Hand every message of the twin's frames (and markers) to a view, under absolute names."""

    def __init__(self, view: FoxgloveView, names: Dict[contract.Topic, str]) -> None:
        self._view = view
        self._names = names

    def on_frame(self, frame: Frame) -> None:
        """Pass the step's messages on (the view only queues them: it never blocks)."""
        view = self._view
        if not view.active:
            return
        names = self._names
        for topic, stamp_ns, data in frame.messages():
            view.sink(names[topic], stamp_ns, data)

    def on_message(self, topic: contract.Topic, stamp_ns: int, data: bytes) -> None:
        """Pass an off-step message (markers) on."""
        name = self._names.get(topic)
        if name is not None and self._view.active:
            self._view.sink(name, stamp_ns, data)


def attach(composed: Any, address: str, *, stream_rate: float = DEFAULT_STREAM_RATE,
           scene_rate: float = DEFAULT_SCENE_RATE,
           backlog: int = DEFAULT_BACKLOG) -> FoxgloveView:
    """Start a Foxglove server for a composed twin not yet started; return the view.

    :param address: ``[HOST:]PORT`` (host 127.0.0.1 by default; port 0: any free port).
    :param stream_rate: rate of the per-step streams sent to clients [Hz].
    :param scene_rate: rate of the 3D scene [Hz].
    :param backlog: messages queued at most, in the twin and per client [1].
    :raises FoxgloveError: if the address is invalid, the host unknown or the port taken.
    """
    host, port = parse_address(address)
    coordinator = composed.coordinator
    twin = composed.twin
    namespace = coordinator.get_namespace()
    names = {topic: resolve(topic.name, namespace) for topic in contract.STREAMS}
    streams: Dict[str, str] = {names[topic]: topic.type_name for topic in contract.STREAMS}

    def on_command(kind: str, name: str, value: float) -> Optional[str]:
        try:
            if kind == BELT:
                twin.commands.submit_belt(name, value)
            else:
                twin.commands.submit_actuator(name, value)
        except CommandRejected as exc:
            coordinator.report_rejected(exc)
            return str(exc)
        return None

    callbacks = {'step': (Step, coordinator._on_step), 'reset': (Reset, coordinator._on_reset),
                 'spawn_parts': (SpawnParts, coordinator._on_spawn)}
    services = tuple(ServiceSpec(name, type_name, request, response,
                                 _cdr_service(*callbacks[name]))
                     for name, type_name, request, response in SERVICE_TEXTS)
    view = FoxgloveView(composed.cell, streams=streams, namespace=namespace,
                        step_s=composed.cell.settings.step, on_command=on_command,
                        services=services, stream_rate=stream_rate, scene_rate=scene_rate,
                        backlog=backlog)
    view.on_invalid = lambda reason: _count_invalid(twin, coordinator, reason)
    view.start(host, port)
    composed.output.subscribe(_FrameFeed(view, names))
    coordinator.add_counters(lambda: {f'foxglove_{k}': v for k, v in view.counters().items()})
    coordinator.declare_parameter(
        'foxglove', f'{host}:{view.port}',
        ParameterDescriptor(description='address of the Foxglove WebSocket server '
                            '(conveyor-twin run --foxglove)', read_only=True))
    return view


def _count_invalid(twin: Any, coordinator: Any, reason: str) -> None:
    """Count a client message that is no valid command (undecodable, other topic) like a
    rejected command: in ``diagnostics`` and the log."""
    coordinator.report_rejected(twin.commands.reject('foxglove_invalid', reason))
