"""The standalone recorder of ``conveyor-twin record`` (:mod:`conveyor_twin.cli.record` parses its
command line and describes it): a node subscribing with ``raw=True`` to contract topics under a
namespace, each with the contract QoS (history depth at least :data:`MIN_DEPTH`), writing the
received CDR bytes untouched with :class:`~conveyor_twin.record.writer.McapRecorder`.

Log time of a message: the simulation time it carries (``header.stamp``, or a Clock's time,
read from the CDR bytes); for messages without a stamp (commands) the latest simulation time
seen on ``/clock`` (or on the stamped topics when ``/clock`` is not recorded), and the receive
time (system clock) before any simulation time was seen.
"""

from dataclasses import dataclass
import json
import signal
import sys
import time
from typing import Any, Dict, List, Mapping, Optional, Sequence

from rclpy.node import Node
from rclpy.qos import QoSProfile

from conveyor_twin.contract import CLOCK, OfferedQos, Stamp, Topic
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Health
from conveyor_twin.record import qos as record_qos
from conveyor_twin.record import topics as contract
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.ros import endpoints
from conveyor_twin.ros.compat import make_executor, make_future
from conveyor_twin.ros.qos import to_rclpy

#: Smallest history depth of the recorder's subscriptions [messages].
MIN_DEPTH = 100
#: Period of the node's housekeeping timer (stop checks, discovery) [s].
TICK_PERIOD = 0.05
#: Period of graph discovery with ``--discover`` [s].
DISCOVER_PERIOD = 1.0
#: Longest single spin of the executor [s] (see record).
SPIN_TIMEOUT = 0.5
NODE_NAME = 'conveyor_twin_recorder'


def message_class(type_name: str) -> Any:
    """Return the generated Python class of ``pkg/msg/Type``.

    :raises RecordingError: if the interface package is not installed.
    """
    try:
        return endpoints.message_class(type_name)
    except ImportError as err:
        raise RecordingError(str(err)) from None


def subscription_qos(offered: OfferedQos) -> QoSProfile:
    """Return the QoS to subscribe with: the contract's, with a history of at least MIN_DEPTH."""
    qos = to_rclpy(offered)
    qos.depth = max(qos.depth, MIN_DEPTH)
    return qos


class _TopicCount:
    """Receive counters of one topic, with the stamp spacing to estimate transport gaps."""

    __slots__ = ('received', 'first', 'last', 'min_dt')

    def __init__(self) -> None:
        self.received = 0
        self.first: Optional[int] = None
        self.last: Optional[int] = None
        self.min_dt: Optional[int] = None

    def add(self, stamp: Optional[int]) -> None:
        self.received += 1
        if stamp is None:
            return
        if self.first is None:
            self.first = stamp
        elif self.last is not None and stamp > self.last:
            dt = stamp - self.last
            if self.min_dt is None or dt < self.min_dt:
                self.min_dt = dt
        self.last = stamp

    def gaps(self) -> int:
        """Return the stamps missing on an evenly spaced stream (0 when unknown)."""
        if self.first is None or self.last is None or not self.min_dt:
            return 0
        expected = (self.last - self.first) // self.min_dt + 1
        return max(0, int(expected) - self.received)


class RecordNode(Node):
    """Subscribe raw to contract topics and feed every message to a recorder.

    :param recorder: open recorder (the caller closes it).
    :param specs: contract topics to record.
    :param namespace: namespace of the twin's topics.
    :param context: rclpy context.
    :param discover: also record topics found in the graph under the namespace whose type has
        a schema in the recorder (checked every :data:`DISCOVER_PERIOD`).
    """

    def __init__(self, recorder: McapRecorder, specs: Sequence[Topic], *,
                 namespace: str = '', context: Any = None, discover: bool = False,
                 node_name: str = NODE_NAME) -> None:
        super().__init__(node_name, context=context)
        self.recorder = recorder
        self.namespace = namespace
        self.counts: Dict[str, _TopicCount] = {}
        self.skipped: Dict[str, str] = {}
        self.sim_now: Optional[int] = None
        self._clock_topic = False
        self._subs: Dict[str, Any] = {}
        for spec in specs:
            self.add(contract.resolve(spec.name, namespace), spec.type_name, spec.qos,
                     spec.stamp)
        self._discover = discover
        self._next_discover = 0.0

    def add(self, topic: str, type_name: str, offered: OfferedQos,
            stamp: str) -> bool:
        """Subscribe to one topic and declare it to the recorder; return whether it records.

        A topic whose type has no schema or no installed message class is skipped and listed
        in :attr:`skipped` with the reason.
        """
        if topic in self._subs or topic in self.skipped:
            return topic in self._subs
        try:
            msg_class = message_class(type_name)
            if not self.recorder.add_topic(topic, type_name, qos=offered):
                return False
        except RecordingError as err:
            self.skipped[topic] = str(err)
            self.get_logger().warning(f'not recording {topic}: {err}')
            return False
        count = self.counts[topic] = _TopicCount()
        is_clock = stamp == Stamp.CLOCK
        self._clock_topic = self._clock_topic or is_clock
        record = self.recorder.record

        def on_message(data: bytes) -> None:
            t = contract.stamp_ns(stamp, data)
            count.add(t)
            if t is None:
                t = self.sim_now if self.sim_now is not None else time.time_ns()
            elif is_clock or not self._clock_topic:
                self.sim_now = t
            record(topic, t, data)

        self._subs[topic] = self.create_subscription(
            msg_class, topic, on_message, subscription_qos(offered), raw=True)
        return True

    def discover(self) -> List[str]:
        """Subscribe to graph topics under the namespace with a known type; return new ones."""
        prefix = contract.resolve('', self.namespace)
        added = []
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subs or topic in self.skipped or len(types) != 1:
                continue
            if topic != CLOCK.name and not topic.startswith(prefix):
                continue
            spec = contract.spec_of(topic, self.namespace)
            type_name = types[0]
            if spec is not None and spec.type_name != type_name:
                continue
            stamp = spec.stamp if spec else contract.STAMP_BY_TYPE.get(type_name, '')
            offered = spec.qos if spec else record_qos.default_qos(type_name)
            if type_name in _known_types() and self.add(topic, type_name, offered, stamp):
                added.append(topic)
        return added

    def tick(self) -> None:
        """Housekeeping between callbacks: graph discovery when enabled."""
        if self._discover and time.monotonic() >= self._next_discover:
            self._next_discover = time.monotonic() + DISCOVER_PERIOD
            for topic in self.discover():
                self.get_logger().info(f'discovered {topic}')

    def matched(self) -> Dict[str, int]:
        """Return the publisher count of every subscribed topic."""
        return {topic: sub.get_publisher_count() for topic, sub in self._subs.items()}


def _known_types() -> frozenset:
    from conveyor_twin.wire.schemas import SCHEMAS
    return frozenset(SCHEMAS)


def summary(node: RecordNode, stats: Any, wall_s: float) -> Dict[str, Any]:
    """Return the end-of-recording summary (plain data).

    :param node: the record node.
    :param stats: :class:`~conveyor_twin.record.writer.RecorderStats` of the closed recorder.
    :param wall_s: recording wall time [s].
    """
    topics = {}
    for topic, count in node.counts.items():
        st = stats.topics.get(topic)
        topics[topic] = {'type': st.type_name if st else '', 'received': count.received,
                         'recorded': st.recorded if st else 0,
                         'decimated': st.decimated if st else 0,
                         'dropped': st.dropped if st else 0, 'gaps': count.gaps()}
    return {'path': stats.path, 'wall_s': round(wall_s, 3), 'topics': topics,
            'skipped': dict(node.skipped), 'dropped': stats.dropped,
            'gaps': sum(t['gaps'] for t in topics.values()), 'error': stats.error}


def format_summary(s: Mapping[str, Any]) -> str:
    """Return the summary as an aligned table."""
    lines = [f"recorded {s['path']} ({s['wall_s']:.1f} s wall)",
             f"  {'topic':<36}{'received':>10}{'recorded':>10}{'decimated':>10}"
             f"{'dropped':>9}{'gaps':>7}"]
    for topic, t in s['topics'].items():
        lines.append(f"  {topic:<36}{t['received']:>10}{t['recorded']:>10}"
                     f"{t['decimated']:>10}{t['dropped']:>9}{t['gaps']:>7}")
    for topic, why in s['skipped'].items():
        lines.append(f'  skipped {topic}: {why}')
    lines.append(f"  dropped (recorder queue full): {s['dropped']}; gaps (lost in transport, "
                 f"estimated): {s['gaps']}")
    return '\n'.join(lines)


def parse_decimation(items: Sequence[str], namespace: str) -> Dict[str, int]:
    """Parse ``NAME=K`` items into {absolute topic: K}.

    :raises ValueError: for a malformed item or K < 1.
    """
    result = {}
    for item in items:
        name, sep, value = item.partition('=')
        if not sep or not value.strip().isdigit() or int(value) < 1:
            raise ValueError(f'--decimate {item!r}: expected NAME=K with an integer K >= 1')
        result[contract.resolve(name.strip(), namespace)] = int(value)
    return result


@dataclass(frozen=True)
class RecordOptions:
    """What ``conveyor-twin record`` records, parsed from its command line.

    :param output: the MCAP file to write (overwritten)
    :param specs: the contract topics to record
    :param decimation: ``{absolute topic: K}``: record every K-th message
    :param namespace: namespace of the twin's topics
    :param discover: also record graph topics under the namespace with a known type
    :param compression: chunk compression (``lz4``, ``zstd``, ``none``)
    :param flush_period: longest wall time between chunk flushes [s]
    :param queue_size: bound of the queue to the writer thread [messages]
    :param duration: stop after this wall time [s] (0: until SIGINT/SIGTERM)
    :param json: print the summary as one JSON object
    """

    output: str
    specs: Sequence[Topic]
    decimation: Mapping[str, int]
    namespace: str = ''
    discover: bool = False
    compression: str = 'lz4'
    flush_period: float = 0.1
    queue_size: int = 20000
    duration: float = 0.0
    json: bool = False


def record(options: RecordOptions) -> int:
    """Record until the duration ends, SIGINT/SIGTERM or a failure of the writer thread; print
    the summary; return 0, 1 if the file cannot be created, or
    :data:`~conveyor_twin.health.EXIT_BACKGROUND_FAILURE` if the writer failed (reported at
    once with its traceback)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    stop = {'signal': 0}

    def on_signal(signum: int, _frame: Any) -> None:
        stop['signal'] = signum

    context = Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    health = Health()
    try:
        recorder = McapRecorder(options.output, compression=options.compression, health=health,
                                flush_period=options.flush_period, queue_size=options.queue_size,
                                decimation=dict(options.decimation),
                                metadata={'recorded_by': 'conveyor-twin record',
                                          'namespace': options.namespace})
    except RecordingError as err:
        print(f'conveyor-twin record: {err}', file=sys.stderr)
        rclpy.try_shutdown(context=context)
        return 1
    executor = make_executor(context)
    node = RecordNode(recorder, options.specs, namespace=options.namespace, context=context,
                      discover=options.discover)
    executor.add_node(node)
    start = time.monotonic()
    done = make_future(executor)

    def tick() -> None:
        node.tick()
        over = options.duration > 0 and time.monotonic() - start >= options.duration
        if (stop['signal'] or over or health.failed) and not done.done():
            done.set_result(True)

    timer = node.create_timer(TICK_PERIOD, tick)
    print(f'recording {len(node.counts)} topics to {options.output}', flush=True)
    code = 0
    try:
        while not done.done():
            # EventsExecutor (rclpy 9.1.2) busy-loops and never returns from
            # spin_until_future_complete without a timeout: always pass one
            executor.spin_until_future_complete(done, timeout_sec=SPIN_TIMEOUT)
    finally:
        node.destroy_timer(timer)
        for topic in list(node.counts):
            node.destroy_subscription(node._subs.pop(topic))
        try:
            stats = recorder.close()
        except RecordingError as err:  # the writer failed: reported when it did
            print(f'conveyor-twin record: {err}', file=sys.stderr)
            stats, code = recorder.stats, EXIT_BACKGROUND_FAILURE
        wall = time.monotonic() - start
        executor.remove_node(node)
        node.destroy_node()
        executor.shutdown()
        rclpy.try_shutdown(context=context)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    s = summary(node, stats, wall)
    print(json.dumps(s, sort_keys=True) if options.json else format_summary(s), flush=True)
    return code
