"""Republishing a recording with its original timing, for ``conveyor-twin replay``
(:mod:`conveyor_twin.cli.replay` parses its command line and describes the verb).

:func:`plan` decides what to publish (topics, QoS, renames, a synthesised ``/clock``),
:func:`schedule` yields the messages of one pass in log-time order, and :class:`Replayer`
publishes the recorded CDR bytes from a node on absolute monotonic deadlines;
:func:`replay` runs it all as the verb does.
"""

from collections import deque
from dataclasses import dataclass, field
import json
import signal
import sys
import threading
import time
from typing import Any, Deque, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np
import yaml

from conveyor_twin.contract import ACTUATOR_COMMAND, BELT_COMMAND, CLOCK
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Health
from conveyor_twin.record import reader, topics as contract
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.qos import default_qos, OfferedQos
from conveyor_twin.record.writer import ACCEPTED_ACTUATOR_COMMANDS, ACCEPTED_BELT_COMMANDS
from conveyor_twin.wire.cdr import encode_clock

#: Busy-wait this long before a deadline instead of sleeping [ns] (sleep wake-up jitter).
SPIN_MARGIN_NS = 150_000
#: GIL switch interval while replaying [s] (Python's default is 5 ms).
SWITCH_INTERVAL = 0.0002
ACCEPTED_PREFIX = '/conveyor_twin/accepted/'
CLOCK_TOPIC = CLOCK.name
CLOCK_TYPE = CLOCK.type_name
_NS_PER_S = 1_000_000_000
#: Name of the read-ahead thread (and of its failure in the replayer's health).
PREFETCH_THREAD = 'replay prefetch thread'


def offered_from_yaml(text: str, type_name: str) -> OfferedQos:
    """Return the first profile of a channel's ``offered_qos_profiles`` text.

    :param text: YAML list as rosbag2 stores it; empty or malformed: the contract default.
    :param type_name: message type, for the default.
    """
    try:
        profiles = yaml.safe_load(text) if text else None
        p = profiles[0]
        return OfferedQos(history=str(p['history']), depth=max(1, int(p['depth'])),
                          reliability=str(p['reliability']),
                          durability=str(p['durability']))
    except Exception:  # noqa: BLE001 - anything unusable falls back to the contract
        return default_qos(type_name)


def _usable(q: OfferedQos, type_name: str) -> OfferedQos:
    """Replace policy values rclpy does not take ('unknown', 'system_default') by defaults."""
    d = default_qos(type_name)
    return OfferedQos(
        history=q.history if q.history in ('keep_last', 'keep_all') else d.history,
        depth=q.depth,
        reliability=q.reliability if q.reliability in ('reliable', 'best_effort')
        else d.reliability,
        durability=q.durability if q.durability in ('volatile', 'transient_local')
        else d.durability)


@dataclass
class ReplayPlan:
    """What a replay publishes: topic -> (type, offered QoS), and the topic renames."""

    path: str
    topics: Dict[str, Tuple[str, OfferedQos]]
    read_topics: List[str]
    rename: Dict[str, str] = field(default_factory=dict)
    synthesize_clock: bool = False
    start_ns: int = 0
    end_ns: int = 0
    step_ns: Optional[int] = None


def plan(path: str, *, topics: Optional[Sequence[str]] = None, clock: bool = True,
         accepted_as_commands: bool = False, namespace: str = '') -> ReplayPlan:
    """Decide what to publish from a recording.

    :param path: the recording (closed; a killed one must be recovered first).
    :param topics: names to replay (absolute, or relative: matching any namespace); None: all
        but the accepted commands. ``/clock`` is published whenever ``clock`` is set.
    :param clock: publish ``/clock`` (recorded, or synthesised from the log times).
    :param accepted_as_commands: publish the accepted commands on ``belt_command`` /
        ``actuator_command`` in ``namespace``.
    :param namespace: namespace of the command topics for ``accepted_as_commands``.
    :raises RecordingError: if the file is not a complete recording or a topic is unknown.
    """
    summary = reader.info(path)
    if not summary['complete']:
        raise RecordingError(f'{path} is not closed (killed recording?): run '
                             f'"conveyor-twin recover {path}" first')
    recorded = summary['topics']
    wanted = None
    if topics is not None:
        wanted = set()
        for name in topics:
            hits = [t for t in recorded if t == name or t == '/' + name.lstrip('/')
                    or t.endswith('/' + name.lstrip('/'))]
            if not hits:
                raise RecordingError(f'{path} has no topic {name!r}; it has '
                                     f'{", ".join(sorted(recorded))}')
            wanted.update(hits)
    result = ReplayPlan(path, {}, [], start_ns=summary['start_ns'], end_ns=summary['end_ns'],
                        step_ns=summary.get('step_ns'))
    commands = {ACCEPTED_BELT_COMMANDS: contract.resolve(BELT_COMMAND.name, namespace),
                ACCEPTED_ACTUATOR_COMMANDS: contract.resolve(ACTUATOR_COMMAND.name, namespace)}
    for topic, t in recorded.items():
        if topic == CLOCK_TOPIC:
            selected = clock
        elif topic.startswith(ACCEPTED_PREFIX):
            selected = accepted_as_commands and topic in commands and (
                wanted is None or topic in wanted)
        else:
            selected = wanted is None or topic in wanted
        if not selected or t['count'] == 0:
            continue
        offered = _usable(offered_from_yaml(t['offered_qos_profiles'], t['type']), t['type'])
        out = commands.get(topic, topic)
        if out != topic:
            result.rename[topic] = out
            offered = default_qos(t['type'])
        result.topics[out] = (t['type'], offered)
        result.read_topics.append(topic)
    if clock and CLOCK_TOPIC not in result.topics:
        result.synthesize_clock = True
        result.topics[CLOCK_TOPIC] = (CLOCK_TYPE, default_qos(CLOCK_TYPE))
    return result


def schedule(p: ReplayPlan, *, start_offset_ns: int = 0) -> Iterator[Tuple[int, str, bytes]]:
    """Yield ``(log_time, topic to publish on, cdr bytes)`` of one pass, in log-time order.

    :param p: the plan.
    :param start_offset_ns: skip messages logged before ``start + offset`` [ns].
    """
    first = p.start_ns + start_offset_ns
    last_clock = None
    for m in reader.read_messages(p.path, topics=p.read_topics):
        if m.log_time < first:
            continue
        if p.synthesize_clock and (last_clock is None or m.log_time > last_clock):
            last_clock = m.log_time
            yield m.log_time, CLOCK_TOPIC, encode_clock(m.log_time)
        yield m.log_time, p.rename.get(m.topic, m.topic), m.data


_LATE_BIN_NS = 10_000  # lateness histogram: 10 us bins up to 100 ms (later: last bin)
_LATE_BINS = 10_000


@dataclass
class ReplayStats:
    """Counters of a replay; lateness = publish time - deadline [ns], as a histogram."""

    published: Dict[str, int] = field(default_factory=dict)
    loops: int = 0
    late: int = 0
    max_lateness_ns: int = 0
    lateness_hist: np.ndarray = field(
        default_factory=lambda: np.zeros(_LATE_BINS, dtype=np.int64))
    wall_s: float = 0.0
    interrupted: bool = False

    def add_lateness(self, late_ns: int) -> None:
        """Count one message published ``late_ns`` after its deadline."""
        self.lateness_hist[min(late_ns // _LATE_BIN_NS, _LATE_BINS - 1)] += 1
        if late_ns > self.max_lateness_ns:
            self.max_lateness_ns = late_ns
        if late_ns > 1_000_000:
            self.late += 1

    def lateness_quantile_ms(self, q: float) -> float:
        """Return the upper edge of the histogram bin holding quantile ``q`` [ms]."""
        total = int(self.lateness_hist.sum())
        if not total:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.lateness_hist), q * total))
        return round((k + 1) * _LATE_BIN_NS / 1e6, 3)

    def as_dict(self) -> Dict[str, Any]:
        """Return plain data with lateness percentiles [ms]."""
        return {'published': dict(self.published), 'loops': self.loops, 'late': self.late,
                'lateness_ms': {'p50': self.lateness_quantile_ms(0.5),
                                'p99': self.lateness_quantile_ms(0.99),
                                'max': round(self.max_lateness_ns / 1e6, 3)},
                'wall_s': round(self.wall_s, 3), 'interrupted': self.interrupted}


def wait_until(deadline_ns: int, spin_margin_ns: int = SPIN_MARGIN_NS) -> int:
    """Sleep, then busy-wait, until ``time.monotonic_ns()`` reaches the deadline.

    :return: lateness [ns] at return (>= 0).
    """
    now = time.monotonic_ns()
    remaining = deadline_ns - now
    if remaining > spin_margin_ns:
        time.sleep((remaining - spin_margin_ns) * 1e-9)
    now = time.monotonic_ns()
    while now < deadline_ns:
        now = time.monotonic_ns()
    return now - deadline_ns


class _Prefetch:
    """Read the schedule in a background thread, ahead of the publisher.

    The indexed reader stalls for tens of milliseconds whenever it loads a chunk; reading
    ahead (up to ``high`` messages, refilled from ``low``) keeps those stalls off the deadlines.
    Items are ``(pass, log_time, topic, data)``; passes repeat with ``loop``; None ends. An
    exception of the reader is reported to ``health`` at once and re-raised by :meth:`get`.
    """

    def __init__(self, p: ReplayPlan, start_offset_ns: int, loop: bool, *,
                 high: int = 20000, low: int = 10000,
                 health: Optional[Health] = None) -> None:
        self._health = health if health is not None else Health()
        self._plan, self._offset, self._loop = p, start_offset_ns, loop
        self._high, self._low = high, low
        self._items: Deque[Any] = deque()
        self._cond = threading.Condition()
        self._stopped = False
        self.error: Optional[BaseException] = None
        self._thread = threading.Thread(target=self._run, name='replay-prefetch', daemon=True)
        self._thread.start()

    def _put(self, item: Any) -> bool:
        with self._cond:
            while len(self._items) >= self._high and not self._stopped:
                self._cond.wait()
            self._items.append(item)
            self._cond.notify_all()
            return not self._stopped

    def _run(self) -> None:
        try:
            k = 0
            while True:
                produced = False
                for log_time, topic, data in schedule(self._plan, start_offset_ns=self._offset):
                    produced = True
                    if not self._put((k, log_time, topic, data)):
                        return
                if not (self._loop and produced):
                    break
                k += 1
        except BaseException as err:  # noqa: BLE001 - re-raised in the publisher's thread
            self.error = err
            self._health.report(PREFETCH_THREAD, err)
        self._put(None)

    def get(self) -> Any:
        """Return the next item (blocking while the reader is behind); None at the end."""
        with self._cond:
            while not self._items:
                self._cond.wait()
            item = self._items.popleft()
            if len(self._items) <= self._low:
                self._cond.notify_all()
        if item is None and self.error is not None:
            raise self.error
        return item

    def stop(self) -> None:
        """Stop reading ahead."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()


class Replayer:
    """Publish a :class:`ReplayPlan` from a node, paced on absolute monotonic deadlines.

    :param node: rclpy node that owns the publishers.
    :param p: what to publish.
    :param rate: replay speed factor (2: twice as fast) [1].
    :param start_offset: skip this much recorded time from the start [s].
    :param loop: start over at the end, until stopped.
    :param spin_margin_ns: busy-wait margin before each deadline [ns].
    """

    def __init__(self, node: Any, p: ReplayPlan, *, rate: float = 1.0,
                 start_offset: float = 0.0, loop: bool = False,
                 spin_margin_ns: int = SPIN_MARGIN_NS) -> None:
        from conveyor_twin.ros.qos import to_rclpy
        from conveyor_twin.ros.record_node import message_class

        if not rate > 0:
            raise ValueError(f'rate must be positive, not {rate}')
        self.plan = p
        self.rate = float(rate)
        self.start_offset_ns = int(round(start_offset * _NS_PER_S))
        self.loop = loop
        self.spin_margin_ns = spin_margin_ns
        self.stats = ReplayStats()
        self.stopped = False
        #: Where the read-ahead thread reports its failure.
        self.health = Health()
        self.publishers = {topic: node.create_publisher(message_class(type_name), topic,
                                                        to_rclpy(offered))
                           for topic, (type_name, offered) in p.topics.items()}

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait until every publisher has a subscriber (or the timeout passes).

        :param timeout: longest wait [s].
        :return: True if every publisher matched.
        """
        deadline = time.monotonic() + timeout
        while not self.stopped:
            if all(pub.get_subscription_count() > 0 for pub in self.publishers.values()):
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)
        return False

    def stop(self) -> None:
        """Ask :meth:`run` to return after the current message (thread- and signal-safe)."""
        self.stopped = True

    def wait_for_acks(self, timeout: float) -> bool:
        """Wait until every subscriber acknowledged what was published (reliable topics).

        A reliable writer that is destroyed right after its last ``publish`` can take
        unacknowledged samples with it; the last messages of a replay would be lost.

        :param timeout: longest wait, shared by all publishers [s].
        :return: True if everything was acknowledged in time.
        """
        from rclpy.duration import Duration

        deadline = time.monotonic() + timeout
        ok = True
        for pub in self.publishers.values():
            left = max(0.0, deadline - time.monotonic())
            ok = pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))) and ok
        return ok

    def run(self) -> ReplayStats:
        """Publish until the end of the recording (or forever with ``loop``, until stopped).

        The wall clock of the replay starts when the first message has been read.

        :raises RecordingError: if the recording cannot be read.
        """
        stats, pubs = self.stats, self.publishers
        published = stats.published
        rate = self.rate
        period = None
        start = time.monotonic_ns()
        t0 = None
        current = -1
        first = last = 0
        switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL)  # the reader thread yields the GIL sooner
        prefetch = _Prefetch(self.plan, self.start_offset_ns, self.loop, health=self.health)
        try:
            while not self.stopped:
                item = prefetch.get()
                if item is None:
                    break
                k, log_time, topic, data = item
                if k != current:
                    if t0 is None:
                        t0 = time.monotonic_ns()
                    else:
                        stats.loops += 1
                        t0 += int((last - first + (period or self.plan.step_ns or 1_000_000))
                                  / rate)
                    current, first = k, log_time
                elif period is None and log_time > last:
                    period = log_time - last
                last = log_time
                late = wait_until(t0 + int((log_time - first) / rate), self.spin_margin_ns)
                pubs[topic].publish(data)
                stats.add_lateness(late)
                published[topic] = published.get(topic, 0) + 1
        finally:
            prefetch.stop()
            sys.setswitchinterval(switch)
        stats.wall_s = (time.monotonic_ns() - start) / 1e9
        stats.interrupted = self.stopped
        return stats


@dataclass(frozen=True)
class ReplayOptions:
    """What ``conveyor-twin replay`` does, parsed from its command line.

    :param file: the MCAP recording
    :param rate: speed factor (2: twice as fast) [1] (> 0)
    :param loop: start over at the end until stopped
    :param start_offset: skip this much recorded time from the start [s] (>= 0)
    :param topics: topics to replay (None: all but the accepted commands)
    :param clock: publish ``/clock``
    :param accepted_as_commands: publish the accepted commands on the command topics
    :param namespace: namespace of the command topics for ``accepted_as_commands``
    :param wait_for_subscribers: before starting, wait up to this long until every topic has
        a subscriber [s] (0: do not wait)
    :param delay: wait this long before the first message (after matching) [s]
    :param linger: at the end, wait up to this long for reliable subscribers'
        acknowledgements [s]
    :param json: print the summary as one JSON object
    """

    file: str
    rate: float = 1.0
    loop: bool = False
    start_offset: float = 0.0
    topics: Optional[Sequence[str]] = None
    clock: bool = True
    accepted_as_commands: bool = False
    namespace: str = ''
    wait_for_subscribers: float = 0.0
    delay: float = 0.0
    linger: float = 5.0
    json: bool = False


def replay(options: ReplayOptions) -> int:
    """Replay a recording and print the summary; return 0, or 1 if it cannot be read,
    :data:`~conveyor_twin.health.EXIT_BACKGROUND_FAILURE` if the read-ahead thread failed
    otherwise (reported with its traceback)."""
    try:
        p = plan(options.file, topics=options.topics, clock=options.clock,
                 accepted_as_commands=options.accepted_as_commands, namespace=options.namespace)
    except RecordingError as err:
        print(f'conveyor-twin replay: {err}', file=sys.stderr)
        return 1
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    context = Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('conveyor_twin_replay', context=context)
    replayer = Replayer(node, p, rate=options.rate, start_offset=options.start_offset,
                        loop=options.loop)
    previous = {sig: signal.signal(sig, lambda *_: replayer.stop())
                for sig in (signal.SIGINT, signal.SIGTERM)}
    code = 0
    try:
        if options.wait_for_subscribers > 0:
            matched = replayer.wait_for_subscribers(options.wait_for_subscribers)
            if not matched:
                print('conveyor-twin replay: not every topic has a subscriber; starting anyway',
                      file=sys.stderr, flush=True)
        if options.delay > 0:
            time.sleep(options.delay)
        topics = ', '.join(sorted(p.topics))
        print(f'replaying {options.file} at rate {options.rate:g}: {topics}', flush=True)
        stats = replayer.run()
    except RecordingError as err:
        print(f'conveyor-twin replay: {err}', file=sys.stderr)
        stats, code = replayer.stats, 1
    except Exception:  # noqa: BLE001 - the read-ahead thread's failure, reported there
        if not replayer.health.failed:
            raise
        stats, code = replayer.stats, EXIT_BACKGROUND_FAILURE
    finally:
        if not replayer.wait_for_acks(options.linger):
            print('conveyor-twin replay: not every subscriber acknowledged the last messages '
                  f'within {options.linger:g} s', file=sys.stderr, flush=True)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    s = stats.as_dict()
    if options.json:
        print(json.dumps(s, sort_keys=True), flush=True)
    else:
        lat = s['lateness_ms']
        print(f"published {sum(s['published'].values())} messages in {s['wall_s']:.3f} s "
              f"({s['loops']} loops{', interrupted' if s['interrupted'] else ''}); lateness "
              f"p50 {lat['p50']} ms, p99 {lat['p99']} ms, max {lat['max']} ms, "
              f"{s['late']} > 1 ms late", flush=True)
        for topic, n in sorted(s['published'].items()):
            print(f'  {topic:<40}{n:>10}')
    return code
