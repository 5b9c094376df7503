"""In-process recording of the composed twin (``conveyor-twin run --record FILE.mcap``).

The composed twin's nodes publish CDR bytes built straight from numpy. :func:`tap` puts a thin
proxy in front of each of their publishers that hands those very bytes to a sink before
publishing them (diagnostics, published as a message object, are serialized once and the bytes
published; a node's shortcut to the publisher's ``handle.publish_raw`` is routed through the
proxy too), so what is recorded is byte for byte what subscribers receive, every step, with
nothing lost to transport. :class:`TwinRecording` feeds them to a
:class:`~conveyor_twin.record.writer.McapRecorder` (which only appends to a bounded queue: the
step never blocks on disk; a full queue drops messages and counts them per topic) and adds,
from a step listener, every accepted command with the step at which it took effect.

``conveyor-twin resimulate`` (:mod:`conveyor_twin.ros.resimulate`) uses the same tap with
``forward=False`` to collect the bytes of a re-run without publishing them.

Log time of a recorded message: the simulation time it carries (``header.stamp``; a Clock's
time), else (markers) the simulation time when it was published (the micro node builds
markers off the stepping thread: at or a few steps after the step they show, which is the
latest stamp of their markers).
"""

import argparse
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

from rclpy.serialization import serialize_message

from conveyor_twin.cell import default_cell_text
from conveyor_twin.coord.commands import ACTUATOR, BELT, Command, CommandRejected
from conveyor_twin.record import topics as contract
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.ros.qos import RawPublisher
from conveyor_twin.wire import cdr

#: (node attribute of ComposedTwin, publisher attribute of that node) of every published stream.
PUBLISHERS: Tuple[Tuple[str, str], ...] = (
    ('micro_node', 'parts_pub'), ('micro_node', 'barrier_pub'), ('micro_node', 'edge_pub'),
    ('micro_node', 'markers_pub'), ('macro_node', 'density_pub'),
    ('coordinator', 'clock_pub'), ('coordinator', 'belt_pub'),
    ('coordinator', 'actuator_pub'), ('coordinator', 'diag_pub'))

Sink = Callable[[str, bytes], None]


class TapPublisher:
    """A publisher proxy that gives every published message's CDR bytes to a sink first.

    :param publisher: the rclpy publisher.
    :param sink: called with (absolute topic name, CDR bytes).
    :param forward: also publish (False: only collect, for re-simulation).
    """

    __slots__ = ('publisher', 'sink', 'topic', 'forward')

    def __init__(self, publisher: Any, sink: Sink, *, forward: bool = True) -> None:
        self.publisher = publisher
        self.sink = sink
        self.topic = publisher.topic_name
        self.forward = forward

    def publish(self, msg: Any) -> None:
        """Hand the message's bytes to the sink, then publish them."""
        data = msg if isinstance(msg, bytes) else serialize_message(msg)
        self.sink(self.topic, data)
        if self.forward:
            self.publisher.publish(data)

    def publish_raw(self, data: bytes) -> None:
        """Hand CDR bytes to the sink, then publish them without rclpy's wrapper."""
        self.sink(self.topic, data)
        if self.forward:
            self.publisher.handle.publish_raw(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.publisher, name)


def _replace_raw_publishers(node: Any, publisher: Any, proxy: TapPublisher) -> None:
    """Route a node's :class:`~conveyor_twin.ros.qos.RawPublisher` shortcuts of ``publisher``
    through the proxy, whatever the node calls them."""
    for value in list(vars(node).values()):
        if isinstance(value, RawPublisher) and value.publisher is publisher:
            value.send = proxy.publish_raw


def tap(composed: Any, sink: Sink, *, forward: bool = True) -> Dict[str, contract.TopicSpec]:
    """Put a :class:`TapPublisher` in front of every stream publisher of a composed twin.

    :param composed: a :class:`~conveyor_twin.ros.compose.ComposedTwin` not yet started.
    :param sink: called with (absolute topic, CDR bytes) for every message published.
    :param forward: also publish the messages.
    :return: the contract entry of every tapped topic, by absolute name.
    :raises RuntimeError: if a publisher is missing (the node suite changed under the tap).
    """
    namespace = composed.coordinator.get_namespace()
    tapped = {}
    for node_name, attribute in PUBLISHERS:
        node = getattr(composed, node_name, None)
        publisher = getattr(node, attribute, None)
        if publisher is None:
            raise RuntimeError(f'cannot record: ComposedTwin.{node_name}.{attribute} is missing')
        if isinstance(publisher, TapPublisher):
            raise RuntimeError(f'{node_name}.{attribute} is tapped already')
        proxy = TapPublisher(publisher, sink, forward=forward)
        spec = contract.spec_of(proxy.topic, namespace)
        if spec is None:
            raise RuntimeError(f'{proxy.topic} is not a contract topic')
        _replace_raw_publishers(node, publisher, proxy)
        setattr(node, attribute, proxy)
        tapped[proxy.topic] = spec
    return tapped


def encode_command(command: Command) -> bytes:
    """Return the BeltCommand/ActuatorCommand CDR of an accepted command."""
    if command.kind == BELT:
        return cdr.encode_belt_command(command.name, command.value)
    return cdr.encode_actuator_command(command.name, command.value)


class TwinRecording:
    """Record a composed twin's streams and accepted commands into an :class:`McapRecorder`.

    :param composed: a :class:`~conveyor_twin.ros.compose.ComposedTwin` not yet started.
    :param recorder: the open recorder (closed by :meth:`close`).
    """

    def __init__(self, composed: Any, recorder: McapRecorder) -> None:
        self.composed = composed
        self.recorder = recorder
        self._twin = composed.twin
        self._stamp: Dict[str, str] = {}
        record = recorder.record
        twin = self._twin
        stamp_of = self._stamp

        def sink(topic: str, data: bytes) -> None:
            t = contract.stamp_ns(stamp_of[topic], data)
            record(topic, twin.time_ns if t is None else t, data)

        for topic, spec in tap(composed, sink).items():
            recorder.add_topic(topic, spec.type_name, qos=spec.qos)
            self._stamp[topic] = spec.stamp
        twin.step_listeners.append(self._on_step)
        composed.coordinator.call_listeners.append(self._on_call)

    def _on_step(self, inp: Any, commands: List[Command]) -> None:
        for command in commands:
            self.recorder.record_accepted_command(command.kind, inp.time_ns,
                                                  encode_command(command))

    def _on_call(self, kind: str, time_ns: int, request: Any) -> None:
        """Record an accepted ``spawn_parts`` or ``reset`` call at the time it happened."""
        if kind == 'spawn':
            data = cdr.encode_spawn_request(request.part_type, request.x, request.y,
                                            request.yaw if len(request.yaw) else
                                            [0.0] * len(request.x))
        else:
            data = cdr.encode_reset_request(request.cell_file, request.seed)
        self.recorder.record_accepted_command(kind, time_ns, data)

    def close(self) -> Dict[str, Any]:
        """Close the file (after the twin stopped); return the per-topic counters.

        :raises RecordingError: if the writer failed.
        """
        stats = self.recorder.close()
        topics = {name: {'recorded': t.recorded, 'decimated': t.decimated,
                         'dropped': t.dropped}
                  for name, t in stats.topics.items() if t.offered or t.recorded}
        return {'path': stats.path, 'compression': self.recorder.compression,
                'messages': sum(t['recorded'] for t in topics.values()),
                'dropped': stats.dropped, 'topics': topics}


# -- ``conveyor-twin run`` options ----------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add ``--record`` and its options (as ``conveyor-twin record`` has them) and
    ``--command`` to the parser of ``run``."""
    g = p.add_argument_group('recording (composed layout)')
    g.add_argument('--record', default=None, metavar='FILE.mcap',
                   help='record every stream, /clock, markers, diagnostics and the accepted '
                   'commands in-process to this MCAP file (overwritten)')
    g.add_argument('--record-topics', nargs='+', default=None, metavar='NAME',
                   help='record only these contract topics (default: every published one): '
                   + ', '.join(n for n, s in contract.CONTRACT_TOPICS.items() if not s.command))
    from conveyor_twin.ros.record_node import add_writer_arguments
    add_writer_arguments(g, prefix='record-')
    g.add_argument('--command', nargs='+', default=[], metavar='STEP:KIND:NAME=VALUE',
                   help='apply a command at a step, e.g. 500:belt:main=0.2 '
                   '1200:actuator:pusher=0.05 (validated like belt_command/actuator_command)')


def parse_commands(items: Sequence[str]) -> List[Tuple[int, str, str, float]]:
    """Parse ``STEP:KIND:NAME=VALUE`` items.

    :raises ValueError: naming the malformed item.
    """
    out = []
    for item in items:
        try:
            step_text, kind, rest = item.split(':', 2)
            name, value_text = rest.rsplit('=', 1)
            step, value = int(step_text), float(value_text)
            if step < 1 or kind not in (BELT, ACTUATOR) or not name:
                raise ValueError
        except ValueError:
            raise ValueError(f'--command {item!r}: expected STEP:KIND:NAME=VALUE with STEP >= 1, '
                             'KIND belt or actuator, e.g. 500:belt:main=0.2') from None
        out.append((step, kind, name, value))
    return out


def schedule_commands(composed: Any, items: Sequence[str]) -> None:
    """Validate ``--command`` items and schedule them on the twin's command book.

    :raises ValueError: for a malformed or invalid command (the message names it).
    """
    book = composed.twin.commands
    for step, kind, name, value in parse_commands(items):
        try:
            command = (book.validate_belt(name, value) if kind == BELT
                       else book.validate_actuator(name, value))
        except CommandRejected as exc:
            raise ValueError(f'--command {step}:{kind}:{name}={value}: {exc}') from None
        book.schedule(step, command)


def start_recording(composed: Any, args: argparse.Namespace, *, seed: int,
                    mode: str) -> Optional[TwinRecording]:
    """Apply ``--command`` and, with ``--record``, open the file and tap the twin.

    :return: the recording, or None without ``--record``.
    :raises ValueError: for invalid options (the message names them).
    :raises RecordingError: if the file cannot be created.
    """
    schedule_commands(composed, args.command)
    if not args.record:
        return None
    from conveyor_twin.ros.record_node import parse_decimation
    namespace = composed.coordinator.get_namespace()
    selection = None
    if args.record_topics is not None:
        try:
            specs = contract.select(args.record_topics)
        except KeyError as exc:
            raise ValueError(f'--record-topics: {exc.args[0]}') from None
        selection = [contract.resolve(s.name, namespace) for s in specs]
    decimation = parse_decimation(args.record_decimate, namespace)
    if args.cell:
        try:
            with open(args.cell, encoding='utf-8') as f:
                cell_text = f.read()
        except OSError as exc:
            raise RecordingError(f'cannot read {args.cell} to attach it: {exc}') from None
    else:
        cell_text = default_cell_text()
    recorder = McapRecorder(
        args.record, compression=args.record_compression,
        flush_period=args.record_flush_period, queue_size=args.record_queue_size,
        topics=selection, decimation=decimation, cell_yaml=cell_text, seed=seed,
        step_ns=composed.twin.dt_ns,
        metadata={'recorded_by': 'conveyor-twin run', 'namespace': namespace,
                  'markers_rate': repr(float(args.markers_rate)), 'mode': mode,
                  'cell_file': args.cell or '', 'commands': ' '.join(args.command)},
        on_thread_start=_writer_priority if mode == 'realtime' else None)
    try:
        return TwinRecording(composed, recorder)
    except BaseException:
        recorder.close()
        raise


def _writer_priority() -> None:
    """Give the writer thread the priority of the twin's other helper threads (realtime): the
    timed flush, which bounds what a kill loses, must not wait for other processes."""
    from conveyor_twin.coord.runner import raise_thread_priority, realtime_priority
    raise_thread_priority(realtime_priority(helper=True))


def format_recording(s: Dict[str, Any]) -> str:
    """Return the recording part of ``run``'s summary as text."""
    lines = [f"  recorded {s['messages']} messages to {s['path']} ({s['compression']}); "
             f"dropped (queue full): {s['dropped']}"]
    for topic, t in s['topics'].items():
        extra = ''.join(f', {k} {t[k]}' for k in ('decimated', 'dropped') if t[k])
        lines.append(f"    {topic}: {t['recorded']}{extra}")
    return '\n'.join(lines)
