"""The ROS interface of the twin, once: every stream, command and service as plain data.

Each entry names the topic or service (relative, so a namespace moves it; ``/clock`` is
absolute as simulators publish it), its type by full name (``pkg/msg/Type``), the QoS the
twin offers (:class:`OfferedQos`, policy names as rmw spells them), how often it is emitted,
how it is stamped and which stage of the twin produces it. No rclpy here: the nodes create
their publishers, subscriptions and services from this table (:mod:`conveyor_twin.ros.endpoints`
maps it to rclpy), the recorder declares its channels from it, readers pick their decoders by
its type names, and a new sink (a viewer, a test harness) reads it to know what a
:class:`~conveyor_twin.output.frame.Frame` carries.
"""

from dataclasses import dataclass
import enum
from typing import Dict, Optional, Tuple

#: Steps between two ``diagnostics`` messages (1 Hz of simulation time at a 1 ms step).
DIAGNOSTICS_PERIOD_STEPS = 1000


@dataclass(frozen=True)
class OfferedQos:
    """One QoS profile (policy names as rmw's ``*_to_str`` spells them; durations infinite).

    :param depth: history depth [messages].
    """

    history: str = 'keep_last'
    depth: int = 100
    reliability: str = 'reliable'
    durability: str = 'volatile'
    liveliness: str = 'automatic'


#: Every-step streams: reliable, keep-last 100, so best-effort and reliable subscribers can both
#: attach and a subscriber in another process loses nothing at 1 kHz.
STREAM_QOS = OfferedQos()
#: Light-barrier edges: reliable with a deeper history.
EDGE_QOS = OfferedQos(depth=1000)
#: ``/clock`` as simulators publish it (rclcpp::ClockQoS): best effort, keep-last 1.
CLOCK_QOS = OfferedQos(depth=1, reliability='best_effort')
#: Commands from controllers.
COMMAND_QOS = OfferedQos(depth=100)
#: Diagnostics (1 Hz) and markers (viewer rate).
SLOW_QOS = OfferedQos(depth=10)
#: The active faults, sent on change: latched (transient local), so a late joiner gets the
#: latest states (the last is the current set); deep enough that a burst of changes is not lost.
LATCHED_QOS = OfferedQos(depth=100, durability='transient_local')
#: The links of a plant: reliable, keep-all, so no batch of parts is ever dropped from the
#: history (docs/plant.md).
PLANT_QOS = OfferedQos(history='keep_all', depth=1000)


class Kind(str, enum.Enum):
    """Direction of an entry: what the twin emits, takes, or serves."""

    STREAM = 'stream'
    COMMAND = 'command'
    SERVICE = 'service'


class Stamp(str, enum.Enum):
    """Where the simulation time of a message is.

    ``HEADER``: ``header.stamp`` (the step's time; an edge's interpolated time);
    ``CLOCK``: the message is the time (``rosgraph_msgs/Clock``); ``NONE``: no time.
    Both stamped kinds carry it as the first field, so it is the first 8 payload bytes.
    """

    HEADER = 'header'
    CLOCK = 'clock'
    NONE = ''


class Rate(str, enum.Enum):
    """How often a stream is emitted."""

    STEP = 'every step'
    EDGE = 'on each change'
    DIAGNOSTICS = 'every DIAGNOSTICS_PERIOD_STEPS steps'
    VIEWER = 'viewer rate (markers_rate), built off the stepping thread'
    ON_DEMAND = 'when a controller sends or calls'
    SYNC = 'every sync period of a plant, and whenever a cell waits for its neighbours'


class Producer(str, enum.Enum):
    """The stage (and, split, the process) that produces a stream or serves an entry."""

    COORDINATOR = 'coordinator'
    MICRO = 'micro'
    MACRO = 'macro'
    PLANT = 'plant'


@dataclass(frozen=True)
class Topic:
    """One entry of the contract.

    :param name: relative topic or service name (``/clock`` absolute).
    :param type_name: full type name, ``pkg/msg/Type`` (services ``pkg/srv/Type``).
    :param kind: stream (out), command (in) or service.
    :param qos: the QoS the twin offers (streams) or subscribes with (commands).
    :param rate: how often it is emitted.
    :param stamp: where its simulation time is.
    :param producer: the stage that produces it (streams) or takes it (commands, services).
    :param default: recorded by default (``markers`` is opt-in: viewer data).
    """

    name: str
    type_name: str
    kind: Kind
    qos: OfferedQos
    rate: Rate
    stamp: Stamp
    producer: Producer
    default: bool = True

    @property
    def command(self) -> bool:
        """True for an input of the twin (a replay publishing it drives a live twin)."""
        return self.kind is Kind.COMMAND


_MSGS = 'conveyor_twin_msgs/msg/'
_SRVS = 'conveyor_twin_msgs/srv/'
_S, _C, _V = Kind.STREAM, Kind.COMMAND, Kind.SERVICE
_COORD, _MICRO, _MACRO = Producer.COORDINATOR, Producer.MICRO, Producer.MACRO

PARTS = Topic('parts', _MSGS + 'PartStates', _S, STREAM_QOS, Rate.STEP, Stamp.HEADER, _MICRO)
DENSITY = Topic('density', _MSGS + 'DensityGrid', _S, STREAM_QOS, Rate.STEP, Stamp.HEADER,
                _MACRO)
LIGHT_BARRIERS = Topic('light_barriers', _MSGS + 'LightBarrierStates', _S, STREAM_QOS,
                       Rate.STEP, Stamp.HEADER, _MICRO)
LIGHT_BARRIER_EDGES = Topic('light_barrier_edges', _MSGS + 'LightBarrierEdge', _S, EDGE_QOS,
                            Rate.EDGE, Stamp.HEADER, _MICRO)
BELT_STATES = Topic('belt_states', _MSGS + 'BeltStates', _S, STREAM_QOS, Rate.STEP,
                    Stamp.HEADER, _COORD)
ACTUATOR_STATES = Topic('actuator_states', _MSGS + 'ActuatorStates', _S, STREAM_QOS, Rate.STEP,
                        Stamp.HEADER, _COORD)
CLOCK = Topic('/clock', 'rosgraph_msgs/msg/Clock', _S, CLOCK_QOS, Rate.STEP, Stamp.CLOCK,
              _COORD)
DIAGNOSTICS = Topic('diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', _S, SLOW_QOS,
                    Rate.DIAGNOSTICS, Stamp.HEADER, _COORD)
MARKERS = Topic('markers', 'visualization_msgs/msg/MarkerArray', _S, SLOW_QOS, Rate.VIEWER,
                Stamp.NONE, _MICRO, default=False)
BELT_COMMAND = Topic('belt_command', _MSGS + 'BeltCommand', _C, COMMAND_QOS, Rate.ON_DEMAND,
                     Stamp.NONE, _COORD)
ACTUATOR_COMMAND = Topic('actuator_command', _MSGS + 'ActuatorCommand', _C, COMMAND_QOS,
                         Rate.ON_DEMAND, Stamp.NONE, _COORD)
STEP = Topic('step', _SRVS + 'Step', _V, COMMAND_QOS, Rate.ON_DEMAND, Stamp.NONE, _COORD)
RESET = Topic('reset', _SRVS + 'Reset', _V, COMMAND_QOS, Rate.ON_DEMAND, Stamp.NONE, _COORD)
SPAWN_PARTS = Topic('spawn_parts', _SRVS + 'SpawnParts', _V, COMMAND_QOS, Rate.ON_DEMAND,
                    Stamp.NONE, _COORD)
#: The outcome of every command received: level OK (accepted, takes effect at the next step) or
#: ERROR (rejected, never applied; ``message`` is the reason), ``name`` the command topic,
#: ``hardware_id`` the belt or actuator, values ``value`` and ``step`` (when it arrived).
COMMAND_STATUS = Topic('command_status', 'diagnostic_msgs/msg/DiagnosticStatus', _S,
                       COMMAND_QOS, Rate.ON_DEMAND, Stamp.NONE, _COORD, default=False)

FAULTS = Topic('faults', _MSGS + 'FaultState', _S, LATCHED_QOS, Rate.EDGE, Stamp.HEADER, _COORD)
INJECT_FAULT = Topic('inject_fault', _SRVS + 'InjectFault', _V, COMMAND_QOS, Rate.ON_DEMAND,
                     Stamp.NONE, _COORD)
CLEAR_FAULT = Topic('clear_fault', _SRVS + 'ClearFault', _V, COMMAND_QOS, Rate.ON_DEMAND,
                    Stamp.NONE, _COORD)

#: Every stream the twin emits.
STREAMS: Tuple[Topic, ...] = (PARTS, DENSITY, LIGHT_BARRIERS, LIGHT_BARRIER_EDGES, BELT_STATES,
                              ACTUATOR_STATES, CLOCK, DIAGNOSTICS, MARKERS, FAULTS)
#: Every command topic the twin subscribes to.
COMMANDS: Tuple[Topic, ...] = (BELT_COMMAND, ACTUATOR_COMMAND)
#: Every service the twin serves.
SERVICES: Tuple[Topic, ...] = (STEP, RESET, SPAWN_PARTS, INJECT_FAULT, CLEAR_FAULT)
#: Answers to commands, published when a command arrives (not part of a step's frame).
REPLIES: Tuple[Topic, ...] = (COMMAND_STATUS,)
#: Topics (streams, commands and replies) by name, as written above.
TOPICS: Dict[str, Topic] = {t.name: t for t in STREAMS + COMMANDS + REPLIES}
#: Every entry of the contract by name.
CONTRACT: Dict[str, Topic] = {t.name: t for t in STREAMS + COMMANDS + REPLIES + SERVICES}


def produced_by(producer: Producer) -> Tuple[Topic, ...]:
    """Return the streams a stage produces (what its process's frames carry)."""
    return tuple(t for t in STREAMS if t.producer is producer)


class Shape(str, enum.Enum):
    """What one step's frame holds of a stream.

    ``ONE``: the bytes of one message, or None when the step emits none; ``MANY``: a sequence
    of messages (one per macro zone) stamped with the step; ``STAMPED``: a sequence of
    (stamp [ns], bytes), each message with its own time (light-barrier edges).
    """

    ONE = 'one'
    MANY = 'many'
    STAMPED = 'stamped'


@dataclass(frozen=True)
class FrameSlot:
    """Where the frame of a step (:class:`conveyor_twin.output.frame.Frame`) carries a stream.

    :param topic: the contract stream.
    :param attribute: the frame's attribute holding its bytes.
    :param shape: one message or a sequence (:class:`Shape`).
    :param outage: a ``stream_outage`` fault may silence it.
    """

    topic: Topic
    attribute: str
    shape: Shape = Shape.ONE
    outage: bool = True

    @property
    def empty(self) -> Optional[tuple]:
        """The attribute's value when the step emits nothing of the stream (None or ())."""
        return None if self.shape is Shape.ONE else ()


#: Every stream a step emits, with its place in the frame, in the order every sink hands them
#: on (and a recording holds them within a step). The one-message streams come first, then
#: the sequences (sinks loop over each shape apart). A new per-step stream is an entry here,
#: its ``Topic`` above and its producer's encoder.
FRAME: Tuple[FrameSlot, ...] = (
    FrameSlot(CLOCK, 'clock'), FrameSlot(BELT_STATES, 'belt_states'),
    FrameSlot(ACTUATOR_STATES, 'actuator_states'), FrameSlot(DIAGNOSTICS, 'diagnostics'),
    FrameSlot(PARTS, 'parts'), FrameSlot(LIGHT_BARRIERS, 'light_barriers'),
    FrameSlot(FAULTS, 'faults', outage=False),
    FrameSlot(LIGHT_BARRIER_EDGES, 'edges', Shape.STAMPED),
    FrameSlot(DENSITY, 'density', Shape.MANY))


def frame_streams(producer: Producer) -> Tuple[Topic, ...]:
    """Return the streams of the frame a stage produces (what its node publishes from its
    frames), in frame order."""
    return tuple(s.topic for s in FRAME if s.topic.producer is producer)


#: The streams a ``stream_outage`` fault may silence, in the order of :data:`STREAMS`.
OUTAGE_STREAMS: Tuple[Topic, ...] = tuple(
    t for t in STREAMS if any(s.topic is t and s.outage for s in FRAME))


# --- a plant of cells (docs/plant.md): names relative to the plant's namespace, ``{link}``
# standing for a link's name; every cell's own interface (above) is under its namespace.
_PLANT = Producer.PLANT
#: Parts that left through a link and how far its exit cell has run (published by the exit).
PART_TRANSFER = Topic('links/{link}/transfer', _MSGS + 'PartTransfer', _S, PLANT_QOS,
                      Rate.SYNC, Stamp.HEADER, _PLANT)
#: Parts the entry cell inserted and how far it has run (published by the entry).
TRANSFER_ACCEPTED = Topic('links/{link}/accepted', _MSGS + 'TransferAccepted', _S, PLANT_QOS,
                          Rate.SYNC, Stamp.HEADER, _PLANT)
#: Every cell's progress and part counts (the plant-wide ledger is built from them); only the
#: latest matters, so keep-last: at most every 0.2 s of wall time, and when the cell is done.
CELL_PROGRESS = Topic('progress', _MSGS + 'CellProgress', _S, STREAM_QOS, Rate.SYNC,
                      Stamp.HEADER, _PLANT)
#: The plant-wide ledger and progress, status ``conveyor_twin: plant`` (1 Hz of wall time,
#: from ``conveyor-twin plant``).
PLANT_DIAGNOSTICS = Topic('diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', _S, SLOW_QOS,
                          Rate.DIAGNOSTICS, Stamp.HEADER, _PLANT)
#: The plant's topics by name (relative to the plant's namespace).
PLANT: Dict[str, Topic] = {t.name: t for t in (PART_TRANSFER, TRANSFER_ACCEPTED, CELL_PROGRESS,
                                               PLANT_DIAGNOSTICS)}


def plant_cell_node(cell: str) -> str:
    """Return the name of a plant cell's node (in the plant's namespace; it publishes the
    cell's ``progress`` and its links' batches)."""
    return f'plant_{cell}'


def link_topic(topic: Topic, plant_namespace: str, link: str) -> str:
    """Return the absolute name of a link's topic (``/<plant namespace>/links/<link>/...``)."""
    return '/' + plant_namespace.strip('/') + '/' + topic.name.format(link=link)
