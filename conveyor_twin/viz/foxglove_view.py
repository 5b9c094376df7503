"""A Foxglove WebSocket server in the twin's process (``foxglove-sdk``), fed with the twin's bytes.

The view is a sink of the twin's frames (:meth:`FoxgloveView.on_frame`, composed layout) or of
single messages (:meth:`FoxgloveView.sink`, as (absolute topic, simulation time [ns], CDR
bytes): the split layout's coordinator, which receives the scale streams over ROS). The ROS side
feeds it only while a client is subscribed (:attr:`FoxgloveView.on_active` is called when the
first subscription arrives and when the last one goes), so with no client the step pays
nothing. With a client, every ``every``-th frame (``stream_rate``) is forwarded whole and the
others only for their edges and diagnostics; the view keeps the latest message of the streams
the scene needs and appends the forwarded ones to a bounded queue (oldest dropped and counted
when full). A publisher thread hands them to the SDK, whose per-client backlog is bounded too,
so a slow or vanished client never stalls the step.

Channels: every contract stream under its ROS topic name, ``cdr`` encoding, ``ros2msg`` schema
(per-step streams forwarded at ``stream_rate``, edges, diagnostics and markers every one); ``scene``
(``visualization_msgs/MarkerArray``: belts, walls, deflectors, pegs, actuators at their current
position, light barriers red while blocked, parts with their shapes) and ``scene/density/ZONE``
(``foxglove.Grid``: the macro density) built by a scene thread at ``scene_rate``, off the
stepping thread. Clients may publish ``belt_command``/``actuator_command`` (``cdr`` or ``json``);
JSON values must be finite JSON numbers (:mod:`conveyor_twin.viz.foxglove_messages`); they go
to ``on_command``, which validates them like the ROS topics. Services (``step``, ``reset``,
``spawn_parts``) take and answer CDR.

The SDK's server listens on a free loopback port behind a
:class:`~conveyor_twin.viz.foxglove_proxy.SubprotocolProxy` at the address asked for, which
accepts both names of the protocol (``foxglove.sdk.v1``, ``foxglove.websocket.v1``). An
exception in the view's threads, or in its callbacks from the SDK, is reported to the twin's
:class:`~conveyor_twin.health.Health` (:data:`SCENE_FAILURE`, ...).

No rclpy here: the ROS side (:mod:`conveyor_twin.ros.foxglove_bridge`) supplies the hooks.
"""

from dataclasses import dataclass
from operator import attrgetter
import socket
from typing import Any, Callable, Dict, List, Optional, Tuple

from conveyor_twin import contract
from conveyor_twin.cell.model import Cell
from conveyor_twin.contract import Shape
from conveyor_twin.health import Health
from conveyor_twin.output.frame import Frame
from conveyor_twin.output.markers import CellMarkers
from conveyor_twin.record.topics import relative, resolve
from conveyor_twin.viz.foxglove_loops import cell_scene, ros_channel, ViewLoops
from conveyor_twin.viz.foxglove_messages import CommandParseError, decode_command, density_grid
from conveyor_twin.wire import cdr

DEFAULT_HOST = '127.0.0.1'
DEFAULT_PORT = 8765
#: Per-step streams are forwarded at this rate by default [Hz].
DEFAULT_STREAM_RATE = 50.0
#: Scene (markers, density grids) rate [Hz].
DEFAULT_SCENE_RATE = 30.0
#: Messages queued between the step and the publisher thread, and per client in the SDK [1].
DEFAULT_BACKLOG = 1024
#: Where the SDK's server listens, behind the subprotocol proxy (any free port).
INNER_HOST = '127.0.0.1'
SCENE_TOPIC = 'scene'
DENSITY_GRID_TOPIC = 'scene/density'
#: Streams sent every message (events and slow streams); the others (emitted every step) at
#: ``stream_rate``.
EVERY_MESSAGE = frozenset(t.name for t in contract.STREAMS if t.rate is not contract.Rate.STEP)
#: Streams whose latest message the scene is drawn from.
SCENE_STREAMS = frozenset(t.name for t in (contract.PARTS, contract.LIGHT_BARRIERS,
                                           contract.ACTUATOR_STATES))
#: Topics clients may publish, and the command kind of each.
COMMAND_TOPICS = {contract.BELT_COMMAND.name: 'belt', contract.ACTUATOR_COMMAND.name: 'actuator'}
#: Names the view's failures are reported under in the twin's :class:`Health`.
PUBLISHER_FAILURE = 'foxglove view (publisher thread)'
SCENE_FAILURE = 'foxglove view (scene thread)'
CLIENT_FAILURE = 'foxglove view (client input)'

CommandHook = Callable[[str, str, float], Optional[str]]
ServiceHandler = Callable[[bytes], bytes]


class FoxgloveError(RuntimeError):
    """The Foxglove server cannot be started (bad address, port in use, SDK missing)."""


@dataclass(frozen=True)
class ServiceSpec:
    """A service offered to Foxglove: ROS type names of request and response, a CDR handler."""

    name: str
    type_name: str
    request_text: str
    response_text: str
    handler: ServiceHandler


def parse_address(text: str) -> Tuple[str, int]:
    """Return (host, port) of ``[HOST:]PORT``; the host defaults to 127.0.0.1.

    :raises FoxgloveError: for a port outside 0..65535 or not a number.
    """
    host, sep, port = text.rpartition(':')
    if not sep:
        host = DEFAULT_HOST
    host = host.strip('[]') or DEFAULT_HOST
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise FoxgloveError(f'--foxglove {text!r}: expected [HOST:]PORT with a port in '
                            '0..65535')
    return host, int(port)


def check_host(host: str) -> None:
    """Raise :class:`FoxgloveError` unless ``host`` resolves to an address of this machine."""
    try:
        socket.getaddrinfo(host, None)
    except (socket.gaierror, UnicodeError) as exc:
        raise FoxgloveError(f'--foxglove: unknown host {host!r} ({exc})') from None


def import_sdk(host: str) -> Any:
    """Check ``host`` (:func:`check_host`) and return the ``foxglove`` SDK module.

    :raises FoxgloveError: if the host is unknown or the SDK is not installed.
    """
    check_host(host)
    try:
        import foxglove
    except ImportError as exc:
        raise FoxgloveError(f'--foxglove needs the foxglove-sdk package ({exc}); '
                            'pip install foxglove-sdk') from None
    return foxglove


def serve(start: Callable[[], Any], host: str, port: int, health: Health) -> Tuple[Any, Any]:
    """Start an SDK server on a free loopback port (``start()``) behind a
    :class:`~conveyor_twin.viz.foxglove_proxy.SubprotocolProxy` at ``host:port``; return both.

    :raises FoxgloveError: if either cannot listen (nothing is left running).
    """
    from conveyor_twin.viz.foxglove_proxy import SubprotocolProxy
    try:
        server = start()
    except Exception as exc:  # the SDK raises its own error types
        raise FoxgloveError(f'--foxglove: the Foxglove server cannot start ({exc})') from None
    try:
        proxy = SubprotocolProxy(host, port, server.port, health=health)
    except OSError as exc:
        server.stop()
        raise FoxgloveError(f'--foxglove {host}:{port}: cannot listen there ({exc})') from None
    return server, proxy


def density_zones(cell: Cell) -> List[str]:
    """Names of the zones of ``cell`` with a density grid (policy ``macro`` or ``auto``)."""
    return [zone.name for zone in cell.zones if zone.policy in ('macro', 'auto')]


def served_topics(cell: Cell, namespace: str = '') -> List[str]:
    """Every topic the view of ``cell`` under ``namespace`` serves: the contract streams, the
    scene and one density grid per macro zone (absolute names)."""
    topics = [resolve(topic.name, namespace) for topic in contract.STREAMS]
    topics.append(resolve(SCENE_TOPIC, namespace))
    topics += [resolve(f'{DENSITY_GRID_TOPIC}/{zone}', namespace)
               for zone in density_zones(cell)]
    return topics


class FoxgloveView(ViewLoops):
    """The Foxglove server of one twin.

    :param cell: the running cell (the scene's geometry).
    :param streams: absolute topic -> full type name of every stream the twin publishes.
    :param namespace: ROS namespace of the twin (topic names are shown as published).
    :param step_s: the twin's step [s].
    :param on_command: called with (``belt``/``actuator``, name, value) for a command published
        by a client; returns None if accepted, else the reason it was rejected.
    :param services: services to offer.
    :param stream_rate: rate of the per-step streams sent to clients [Hz].
    :param scene_rate: rate of the scene [Hz].
    :param backlog: queued messages at most, here and per client in the SDK [1].
    :param health: where the view's threads report an exception (the twin's ``health``;
        default: a health of its own, printed on standard error).
    """

    def __init__(self, cell: Cell, *, streams: Dict[str, str], namespace: str = '',
                 step_s: float, on_command: CommandHook,
                 services: Tuple[ServiceSpec, ...] = (),
                 stream_rate: float = DEFAULT_STREAM_RATE,
                 scene_rate: float = DEFAULT_SCENE_RATE,
                 backlog: int = DEFAULT_BACKLOG,
                 health: Optional[Health] = None) -> None:
        super().__init__(scene_rate=scene_rate, backlog=backlog, health=health)
        self.cell = cell
        self.namespace = namespace
        self.streams = dict(streams)
        self.on_command = on_command
        self.services = services
        every = max(1, int(round(1.0 / (stream_rate * step_s))))
        #: Frames forwarded whole: one in ``every`` [1].
        self.every = every
        self._frames = 0
        self._names = {topic: resolve(topic.name, namespace)
                       for topic in contract.STREAMS}
        #: (absolute topic, frame attribute getter, shape) of the frame's streams sent every
        #: message, in frame order.
        self._every_message = tuple(
            (self._names[s.topic], attrgetter(s.attribute), s.shape) for s in contract.FRAME
            if s.topic.name in EVERY_MESSAGE)
        self._every = {topic: 1 if relative(topic, namespace) in EVERY_MESSAGE
                       else every for topic in self.streams}
        self._count = {topic: 0 for topic in self.streams}
        self._latest: Dict[str, Tuple[int, bytes]] = {}
        self._density: Dict[str, Tuple[int, bytes]] = {}
        self._rel = {topic: relative(topic, namespace) for topic in self.streams}
        self.rejected = 0            # client messages refused (invalid command, bad payload)
        self.last_rejection = ''
        #: Called with the reason of a client message that is no command at all (undecodable,
        #: another topic); rejected commands are reported by ``on_command`` itself.
        self.on_invalid: Callable[[str], None] = lambda reason: None
        self._client_channels: Dict[Tuple[int, int], Tuple[str, str]] = {}
        self._markers = CellMarkers(cell)

    # -- the step side ---------------------------------------------------------------------
    def on_frame(self, frame: Frame) -> None:
        """Take the step's frame (stepping thread: cheap, never blocks).

        One frame in :attr:`every` is forwarded whole; of the others only the edges, the
        diagnostics and the fault state. Bytes are kept, not copied (the twin builds new bytes
        every step).
        """
        n = self._frames
        self._frames = n + 1
        if n % self.every:
            t = frame.time_ns
            for name, get, shape in self._every_message:
                value = get(frame)
                if shape is Shape.ONE:
                    if value is not None:
                        self._enqueue(name, t, value)
                elif shape is Shape.STAMPED:
                    for stamp, data in value:
                        self._enqueue(name, stamp, data)
                else:
                    for data in value:
                        self._enqueue(name, t, data)
            return
        names = self._names
        for topic, stamp_ns, data in frame.messages():
            self._keep(topic.name, stamp_ns, data)
            self._enqueue(names[topic], stamp_ns, data)

    def on_message(self, topic: contract.Topic, stamp_ns: int, data: bytes) -> None:
        """Take a message emitted off the step (``markers``)."""
        name = self._names.get(topic)
        if name is not None and self.active:
            self._enqueue(name, stamp_ns, data)

    def sink(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Take one message of a stream (cheap, never blocks); per-step streams are thinned
        to ``stream_rate`` by counting their messages.

        :param topic: absolute topic name.
        :param stamp_ns: simulation time of the message [ns].
        :param data: its CDR bytes (kept, not copied).
        """
        if not self.active:
            return
        rel = self._rel.get(topic)
        if rel is None:
            return
        n = self._count[topic]
        self._count[topic] = n + 1
        if n % self._every[topic]:
            return
        self._keep(rel, stamp_ns, data)
        self._enqueue(topic, stamp_ns, data)

    def _keep(self, rel: str, stamp_ns: int, data: bytes) -> None:
        """Keep the latest message of the streams the scene is drawn from."""
        if rel == contract.DENSITY.name:
            self._density[_density_zone(data)] = (stamp_ns, data)
        elif rel in SCENE_STREAMS:
            self._latest[rel] = (stamp_ns, data)

    # -- server --------------------------------------------------------------------------
    def start(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT) -> int:
        """Start the server and its threads; return the port it listens on.

        :raises FoxgloveError: if the host is unknown, the port is taken or the SDK is missing.
        """
        foxglove = import_sdk(host)
        from foxglove.websocket import Capability
        context = self._context = foxglove.Context()  # the channels live as long as it
        for topic, type_name in self.streams.items():
            self.channels[topic] = ros_channel(foxglove, context, topic, type_name)
        scene = resolve(SCENE_TOPIC, self.namespace)
        self.channels[scene] = ros_channel(foxglove, context, scene,
                                             'visualization_msgs/msg/MarkerArray')
        from foxglove.channels import GridChannel
        self._grid_channels = {
            zone: GridChannel(resolve(f'{DENSITY_GRID_TOPIC}/{zone}', self.namespace),
                              context=context)
            for zone in density_zones(self.cell)}
        self.server, self.proxy = serve(lambda: foxglove.start_server(
            name=f'conveyor_twin: {self.cell.settings.name}', host=INNER_HOST, port=0,
            capabilities=[Capability.ClientPublish, Capability.Services, Capability.Time],
            server_listener=_Listener(self), supported_encodings=['cdr', 'json'],
            services=[self._service(foxglove, s) for s in self.services],
            context=context, message_backlog_size=self.backlog), host, port, self.health)
        self.port = self.proxy.port
        self._start_threads(PUBLISHER_FAILURE, SCENE_FAILURE)
        return self.port

    def _service(self, foxglove, spec: ServiceSpec):
        from foxglove import MessageSchema, Service, ServiceSchema

        def message_schema(suffix: str, text: str) -> MessageSchema:
            return MessageSchema(encoding='cdr', schema=foxglove.Schema(
                name=f'{spec.type_name}_{suffix}', encoding='ros2msg', data=text.encode()))

        def handler(request) -> bytes:
            return spec.handler(bytes(request.payload))

        return Service(resolve(spec.name, self.namespace), schema=ServiceSchema(
            spec.type_name, request=message_schema('Request', spec.request_text),
            response=message_schema('Response', spec.response_text)), handler=handler)

    def build_scene(self) -> None:
        """Log the scene and density grids of the latest state (scene thread)."""
        scene = cell_scene(self._markers, self.cell, self._latest)
        if scene is None:
            return
        stamp_ns, markers = scene
        self.channels[resolve(SCENE_TOPIC, self.namespace)].log(markers,
                                                                        log_time=stamp_ns)
        for zone, (t_ns, grid_bytes) in list(self._density.items()):
            channel = self._grid_channels.get(zone)
            if channel is not None:
                channel.log(density_grid(cdr.decode_density_grid(grid_bytes)), log_time=t_ns)
        self.server.broadcast_time(stamp_ns)
        self.scenes += 1

    # -- client input ----------------------------------------------------------------------
    def _on_first_subscription(self) -> None:
        self._frames = 0

    def _advertised(self, key: Tuple[int, int], topic: str, encoding: str) -> None:
        self._client_channels[key] = (relative(topic, self.namespace), encoding)

    def _unadvertised(self, key: Tuple[int, int]) -> None:
        self._client_channels.pop(key, None)

    def client_message(self, key: Tuple[int, int], data: bytes) -> Optional[str]:
        """Take a message a client published; return None if applied, else the reason.

        :param key: (client id, client channel id).
        """
        topic, encoding = self._client_channels.get(key, ('', ''))
        kind = COMMAND_TOPICS.get(topic.lstrip('/'))
        if kind is None:
            return self._invalid(f'{topic or "an unadvertised channel"}: clients may publish '
                                 f'only {" and ".join(COMMAND_TOPICS)}')
        try:
            name, value = decode_command(kind, encoding, data)
        except CommandParseError as exc:
            return self._invalid(f'{topic}: invalid {encoding} command, not applied: {exc}')
        reason = self.on_command(kind, name, value)
        if reason is not None:
            return self._reject(reason)
        return None

    def _invalid(self, reason: str) -> str:
        self.on_invalid(reason)
        return self._reject(reason)

    def _reject(self, reason: str) -> str:
        """Count a refused client message and tell the clients why (a status message)."""
        self.rejected += 1
        self.last_rejection = reason
        if self.server is not None:
            from foxglove import StatusLevel
            self.server.publish_status(f'rejected: {reason}', StatusLevel.Warning)
        return reason

    def counters(self) -> Dict[str, float]:
        """Return the view's counters: clients' subscriptions, sent, dropped, rejected
        commands, scenes, clients refused for their subprotocol."""
        return {'subscriptions': len(self._subscriptions), 'sent': self.sent,
                'dropped': self.dropped, 'rejected': self.rejected, 'scenes': self.scenes,
                'refused_clients': self.proxy.refused if self.proxy is not None else 0}


def _density_zone(data: bytes) -> str:
    from conveyor_twin.wire.decoders import density_zone as zone_of
    return zone_of(data)


class _Listener:
    """The SDK's server listener: subscriptions and client channels to the view.

    The SDK calls these on its own thread; an exception is reported to the view's health as
    :data:`CLIENT_FAILURE` (once), not left to the SDK's log.
    """

    def __init__(self, view: FoxgloveView) -> None:
        self.view = view

    def _call(self, target: Callable[..., object], *args) -> None:
        self.view.health.guard(CLIENT_FAILURE, target)(*args)

    def on_subscribe(self, client, channel) -> None:
        self._call(self.view._subscribed, (client.id, channel.id), channel.topic, True)

    def on_unsubscribe(self, client, channel) -> None:
        self._call(self.view._subscribed, (client.id, channel.id), channel.topic, False)

    def on_client_advertise(self, client, channel) -> None:
        self._call(self.view._advertised, (client.id, channel.id), channel.topic,
                   channel.encoding)

    def on_client_unadvertise(self, client, client_channel_id: int) -> None:
        self._call(self.view._unadvertised, (client.id, client_channel_id))

    def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
        self._call(self.view.client_message, (client.id, client_channel_id), data)
