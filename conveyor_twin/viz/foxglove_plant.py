"""One Foxglove server showing every cell of a plant (``conveyor-twin plant --foxglove``).

Fed with single messages of the cells' streams (:meth:`PlantView.sink`: absolute topic,
simulation time [ns], CDR bytes), which the ROS side takes from every cell's namespace while a
client is subscribed (:attr:`PlantView.on_active`), whether the cells run in processes of their
own or in this one. Per-step streams are thinned to ``stream_rate`` by counting.

Channels: each cell's streams under its namespace (``/<cell>/parts``, ``/<cell>/density``,
``light_barriers``, ``light_barrier_edges``, ``belt_states``, ``actuator_states``,
``diagnostics``, ``faults``: ``cdr``, ``ros2msg``), each cell's 3D scene ``/<cell>/scene``
(``visualization_msgs/MarkerArray`` in the cell's frame, named as its namespace) and density
grids ``/<cell>/scene/density/ZONE`` (``foxglove.Grid``), and ``/tf`` (``foxglove.
FrameTransforms``): every cell's frame placed in the plant frame (:func:`plant_frame`) by its
placement. A 3D panel that follows the plant frame shows the whole plant in one scene
(:func:`conveyor_twin.viz.foxglove_layout.plant_layout`). The view is read-only: clients
cannot publish (command a cell on its own ``/<cell>/belt_command`` topic over ROS).
"""

import dataclasses
import math
from typing import Dict, List, Optional, Tuple

from conveyor_twin import contract
from conveyor_twin.health import Health
from conveyor_twin.output.markers import CellMarkers
from conveyor_twin.record.topics import resolve
from conveyor_twin.viz.foxglove_loops import cell_scene, ros_channel, ViewLoops
from conveyor_twin.viz.foxglove_messages import density_grid
from conveyor_twin.viz.foxglove_view import (DEFAULT_BACKLOG, DEFAULT_HOST, DEFAULT_PORT,
                                             DEFAULT_SCENE_RATE, DEFAULT_STREAM_RATE,
                                             DENSITY_GRID_TOPIC, EVERY_MESSAGE, INNER_HOST,
                                             SCENE_STREAMS, SCENE_TOPIC, density_zones,
                                             import_sdk, serve)
from conveyor_twin.wire import cdr

#: The streams of each cell the plant view serves (relative names): every stream of the
#: frame but the clock (the plant's time is every cell's), in the contract's order.
PLANT_STREAMS = tuple(t.name for t in contract.STREAMS
                      if t in {s.topic for s in contract.FRAME} and t is not contract.CLOCK)
TF_TOPIC = '/tf'
PUBLISHER_FAILURE = 'foxglove plant view (publisher thread)'
SCENE_FAILURE = 'foxglove plant view (scene thread)'
CLIENT_FAILURE = 'foxglove plant view (client input)'


def plant_frame(plant) -> str:
    """The frame every cell is placed in: the plant's namespace."""
    return plant.namespace.strip('/') or 'plant'


def plant_topics(plant) -> List[str]:
    """Every topic the plant view serves (absolute names)."""
    topics = [TF_TOPIC]
    for c in plant.cells:
        ns = '/' + c.namespace
        topics += [resolve(name, ns) for name in PLANT_STREAMS]
        topics.append(resolve(SCENE_TOPIC, ns))
        topics += [resolve(f'{DENSITY_GRID_TOPIC}/{z}', ns)
                   for z in density_zones(c.cell)]
    return topics


class _CellScene:
    """The latest state of one cell and what its scene is drawn with."""

    def __init__(self, plant_cell) -> None:
        self.name = plant_cell.name
        self.namespace = '/' + plant_cell.namespace
        self.frame = plant_cell.namespace.strip('/')
        cell = plant_cell.cell
        self.cell = dataclasses.replace(
            cell, settings=dataclasses.replace(cell.settings, frame_id=self.frame))
        self.placement = plant_cell.placement
        self.markers = CellMarkers(self.cell)
        self.latest: Dict[str, Tuple[int, bytes]] = {}
        self.density: Dict[str, Tuple[int, bytes]] = {}


class PlantView(ViewLoops):
    """The Foxglove server of a plant.

    :param plant: the validated plant.
    :param stream_rate: rate of the per-step streams sent to clients [Hz].
    :param scene_rate: rate of the scenes [Hz].
    :param backlog: queued messages at most, here and per client in the SDK [1].
    :param health: where the view's threads report an exception.
    """

    def __init__(self, plant, *, stream_rate: float = DEFAULT_STREAM_RATE,
                 scene_rate: float = DEFAULT_SCENE_RATE, backlog: int = DEFAULT_BACKLOG,
                 health: Optional[Health] = None) -> None:
        super().__init__(scene_rate=scene_rate, backlog=backlog, health=health)
        self.plant = plant
        self.frame = plant_frame(plant)
        every = max(1, int(round(1.0 / (stream_rate * plant.step))))
        self.cells = [_CellScene(c) for c in plant.cells]
        #: absolute topic -> (cell scene, relative stream name, thinning)
        self.streams: Dict[str, Tuple[_CellScene, str, int]] = {}
        for scene in self.cells:
            for name in PLANT_STREAMS:
                self.streams[resolve(name, scene.namespace)] = (
                    scene, name, 1 if name in EVERY_MESSAGE else every)
        self._count = {topic: 0 for topic in self.streams}
        self.channels: Dict[str, object] = {}

    # -- the ROS side ----------------------------------------------------------------------
    def sink(self, topic: str, stamp_ns: int, data: bytes) -> None:
        """Take one message of a cell's stream (cheap, never blocks)."""
        entry = self.streams.get(topic)
        if entry is None or not self.active:
            return
        scene, rel, every = entry
        n = self._count[topic]
        self._count[topic] = n + 1
        if n % every:
            return
        if rel == contract.DENSITY.name:
            scene.density[cdr.decode_density_grid(data).zone] = (stamp_ns, data)
        elif rel in SCENE_STREAMS:
            scene.latest[rel] = (stamp_ns, data)
        self._enqueue(topic, stamp_ns, data)

    # -- server ----------------------------------------------------------------------------
    def start(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT) -> int:
        """Start the server and its threads; return the port it listens on.

        :raises FoxgloveError: if the host is unknown, the port is taken or the SDK is missing.
        """
        foxglove = import_sdk(host)
        from foxglove.channels import FrameTransformsChannel, GridChannel
        from foxglove.websocket import Capability
        context = self._context = foxglove.Context()
        types = {t.name: t.type_name for t in contract.STREAMS}
        for topic, (_, rel, _) in self.streams.items():
            self.channels[topic] = ros_channel(foxglove, context, topic, types[rel])
        self._grids: Dict[Tuple[str, str], object] = {}
        for scene in self.cells:
            topic = resolve(SCENE_TOPIC, scene.namespace)
            self.channels[topic] = ros_channel(foxglove, context, topic,
                                                'visualization_msgs/msg/MarkerArray')
            for zone in density_zones(scene.cell):
                self._grids[scene.name, zone] = GridChannel(
                    resolve(f'{DENSITY_GRID_TOPIC}/{zone}', scene.namespace),
                    context=context)
        self._tf = FrameTransformsChannel(TF_TOPIC, context=context)
        self.server, self.proxy = serve(lambda: foxglove.start_server(
            name=f'conveyor_twin plant: {self.plant.name}', host=INNER_HOST, port=0,
            capabilities=[Capability.Time], server_listener=_Listener(self),
            supported_encodings=['cdr'], context=context,
            message_backlog_size=self.backlog), host, port, self.health)
        self.port = self.proxy.port
        self._start_threads(PUBLISHER_FAILURE, SCENE_FAILURE)
        return self.port

    def build_scene(self) -> None:
        """Log the frames, scenes and density grids of every cell's latest state."""
        stamps = []
        for scene in self.cells:
            drawn = cell_scene(scene.markers, scene.cell, scene.latest)
            if drawn is None:
                continue
            stamp_ns, markers = drawn
            stamps.append(stamp_ns)
            self.channels[resolve(SCENE_TOPIC, scene.namespace)].log(
                markers, log_time=stamp_ns)
            for zone, (t_ns, grid_bytes) in list(scene.density.items()):
                channel = self._grids.get((scene.name, zone))
                if channel is not None:
                    grid = cdr.decode_density_grid(grid_bytes)._replace(frame_id=scene.frame)
                    channel.log(density_grid(grid), log_time=t_ns)
        if not stamps:
            return
        self._tf.log(self._transforms(min(stamps)), log_time=min(stamps))
        self.server.broadcast_time(min(stamps))
        self.scenes += 1

    def _transforms(self, stamp_ns: int):
        from conveyor_twin.viz.foxglove_messages import _messages_module
        m = _messages_module()
        stamp = m.Timestamp(sec=stamp_ns // 1_000_000_000, nsec=stamp_ns % 1_000_000_000)
        return m.FrameTransforms(transforms=[
            m.FrameTransform(timestamp=stamp, parent_frame_id=self.frame,
                             child_frame_id=s.frame,
                             translation=m.Vector3(x=s.placement.x, y=s.placement.y, z=0.0),
                             rotation=m.Quaternion(x=0.0, y=0.0,
                                                   z=math.sin(0.5 * s.placement.yaw),
                                                   w=math.cos(0.5 * s.placement.yaw)))
            for s in self.cells])

    def counters(self) -> Dict[str, float]:
        """Return the view's counters: subscriptions, sent, dropped, scenes."""
        return {'subscriptions': len(self._subscriptions), 'sent': self.sent,
                'dropped': self.dropped, 'scenes': self.scenes}


class _Listener:
    """Subscriptions to the plant view; exceptions are reported to its health."""

    def __init__(self, view: PlantView) -> None:
        self.view = view

    def on_subscribe(self, client, channel) -> None:
        self.view.health.guard(CLIENT_FAILURE, self.view._subscribed)(
            (client.id, channel.id), channel.topic, True)

    def on_unsubscribe(self, client, channel) -> None:
        self.view.health.guard(CLIENT_FAILURE, self.view._subscribed)(
            (client.id, channel.id), channel.topic, False)
