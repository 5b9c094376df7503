"""In-process recording of the composed twin (``conveyor-twin run --record FILE.mcap``).

The recorder is a sink of the twin's output (:class:`~conveyor_twin.record.sink.RecordingSink`):
it takes the same frames the nodes publish, so what is recorded is byte for byte what
subscribers receive, every step, with nothing lost to transport, stamped with the simulation
time the frame carries. :class:`TwinRecording` subscribes it to a composed twin and adds the
accepted ``spawn_parts``/``reset`` calls of the coordinator node.

Log time of a recorded message: its simulation time (the step's; an edge's own), and for
``markers`` (built off the stepping thread at viewer rate) the time of the latest frame when
they were published: at or a few steps after the step they show.
"""

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence, Tuple

from conveyor_twin.cell import default_cell_text
from conveyor_twin.coord.commands import CommandKind, CommandRejected
from conveyor_twin.record import topics as contract
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.sink import RecordingSink
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr


class TwinRecording:
    """Record a composed twin's frames and accepted calls into an :class:`McapRecorder`.

    :param composed: a :class:`~conveyor_twin.ros.compose.ComposedTwin` not yet started.
    :param recorder: the open recorder (closed by :meth:`close`).
    """

    def __init__(self, composed: Any, recorder: McapRecorder) -> None:
        self.composed = composed
        self.recorder = recorder
        self.sink = RecordingSink(recorder, namespace=composed.coordinator.get_namespace())
        composed.output.subscribe(self.sink)
        composed.coordinator.call_listeners.append(self._on_call)

    def _on_call(self, kind: str, time_ns: int, request: Any) -> None:
        """Record an accepted ``spawn_parts`` or ``reset`` call at the time it happened."""
        if kind == 'spawn':
            data = cdr.encode_spawn_request(request.part_type, request.x, request.y,
                                            request.yaw if len(request.yaw) else
                                            [0.0] * len(request.x))
        else:
            data = cdr.encode_reset_request(request.cell_file, request.seed)
        self.sink.record_call(kind, time_ns, data)

    def close(self) -> Dict[str, Any]:
        """Close the file (after the twin stopped); return the per-topic counters.

        :raises RecordingError: if the writer failed.
        """
        self.composed.output.unsubscribe(self.sink)
        stats = self.recorder.close()
        topics = {name: {'recorded': t.recorded, 'decimated': t.decimated,
                         'dropped': t.dropped}
                  for name, t in stats.topics.items() if t.offered or t.recorded}
        return {'path': stats.path, 'compression': self.recorder.compression,
                'messages': sum(t['recorded'] for t in topics.values()),
                'dropped': stats.dropped, 'topics': topics}


# -- ``conveyor-twin run`` options ----------------------------------------------------------
@dataclass(frozen=True)
class RecordingOptions:
    """``run``'s recording options, parsed from its command line
    (:func:`conveyor_twin.cli.record.recording_options`).

    :param path: ``--record``: the MCAP file to write (None: no recording)
    :param topics: ``--record-topics``: contract topics to record (None: every published one)
    :param decimate: ``--record-decimate``: ``NAME=K`` items
    :param compression: ``--record-compression``: ``lz4``, ``zstd`` or ``none``
    :param flush_period: ``--record-flush-period``: longest wall time between flushes [s]
    :param queue_size: ``--record-queue-size``: bound of the writer's queue [messages]
    :param commands: ``--command``: ``STEP:KIND:NAME=VALUE`` items
    :param cell_file: ``--cell``: the cell file attached to the recording ('' : the default)
    :param markers_rate: ``--markers-rate`` [Hz], stored in the metadata
    """

    path: Optional[str] = None
    topics: Optional[Sequence[str]] = None
    decimate: Sequence[str] = ()
    compression: str = 'lz4'
    flush_period: float = 0.1
    queue_size: int = 20000
    commands: Sequence[str] = ()
    cell_file: str = ''
    markers_rate: float = 30.0


def parse_commands(items: Sequence[str]) -> List[Tuple[int, CommandKind, str, float]]:
    """Parse ``STEP:KIND:NAME=VALUE`` items.

    :raises ValueError: naming the malformed item.
    """
    out = []
    for item in items:
        try:
            step_text, kind_text, rest = item.split(':', 2)
            name, value_text = rest.rsplit('=', 1)
            step, value, kind = int(step_text), float(value_text), CommandKind(kind_text)
            if step < 1 or not name:
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
            command = (book.validate_belt(name, value) if kind == CommandKind.BELT
                       else book.validate_actuator(name, value))
        except CommandRejected as exc:
            raise ValueError(f'--command {step}:{kind}:{name}={value}: {exc}') from None
        book.schedule(step, command)


def start_recording(composed: Any, options: RecordingOptions, *, seed: int,
                    mode: str) -> Optional[TwinRecording]:
    """Apply ``--command`` and, with ``--record``, open the file and subscribe a recorder to the twin.

    :return: the recording, or None without ``--record``.
    :raises ValueError: for invalid options (the message names them).
    :raises RecordingError: if the file cannot be created.
    """
    schedule_commands(composed, options.commands)
    if not options.path:
        return None
    from conveyor_twin.ros.record_node import parse_decimation
    namespace = composed.coordinator.get_namespace()
    selection = None
    if options.topics is not None:
        try:
            specs = contract.select(options.topics)
        except KeyError as exc:
            raise ValueError(f'--record-topics: {exc.args[0]}') from None
        selection = [contract.resolve(s.name, namespace) for s in specs]
    decimation = parse_decimation(options.decimate, namespace)
    if options.cell_file:
        try:
            with open(options.cell_file, encoding='utf-8') as f:
                cell_text = f.read()
        except OSError as exc:
            raise RecordingError(f'cannot read {options.cell_file} to attach it: {exc}') \
                from None
    else:
        cell_text = default_cell_text()
    recorder = McapRecorder(
        options.path, compression=options.compression,
        flush_period=options.flush_period, queue_size=options.queue_size,
        topics=selection, decimation=decimation, cell_yaml=cell_text, seed=seed,
        step_ns=composed.twin.dt_ns,
        metadata={'recorded_by': 'conveyor-twin run', 'namespace': namespace,
                  'markers_rate': repr(float(options.markers_rate)), 'mode': mode,
                  'cell_file': options.cell_file or '', 'commands': ' '.join(options.commands),
                  **_scenario_metadata(composed)},
        on_thread_start=_writer_priority if mode == 'realtime' else None,
        health=composed.twin.health)
    try:
        return TwinRecording(composed, recorder)
    except BaseException:
        recorder.close()
        raise


def _scenario_metadata(composed: Any) -> Dict[str, str]:
    """The armed scenario's file and YAML text (the faults themselves are the ``faults``
    stream, which re-simulation replays)."""
    runner = getattr(composed, 'scenario', None)
    if runner is None:
        return {}
    return {'scenario_file': runner.scenario.source_file, 'scenario': runner.scenario.text}


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
