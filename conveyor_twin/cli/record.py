"""``conveyor-twin record``: record a live twin (or any contract publisher) like a user would.

A standalone recorder for systems it does not own: a node subscribing with ``raw=True`` to the
contract topics under a namespace, each with the contract QoS (reliability and durability of
the contract; history depth at least :data:`MIN_DEPTH`, so a busy recorder does not lose a
best-effort ``/clock`` message between two callbacks), writing the received CDR bytes untouched
with :class:`~conveyor_twin.record.writer.McapRecorder` (timed flush, bounded queue, lz4 by
default). The twin's own ``run --record`` records in-process instead and loses nothing at
1 kHz; this one sees what a subscriber in another process sees.

Log time of a message: the simulation time it carries (``header.stamp``, or a Clock's time,
read from the CDR bytes); for messages without a stamp (commands) the latest simulation time
seen on ``/clock`` (or on the stamped topics when ``/clock`` is not recorded), and the receive
time (system clock) before any simulation time was seen.

At the end (``--duration`` of wall time, SIGINT or SIGTERM) the file is closed and valid, and a
summary is printed: per topic the messages received, recorded, decimated, dropped (recorder
queue full) and ``gaps`` (every-step streams: stamps missing between the first and the last,
estimated from the smallest stamp spacing seen: what the transport lost).
"""
import argparse
import sys
from typing import Any, List, Optional, TYPE_CHECKING

from conveyor_twin.contract import TOPICS
from conveyor_twin.record import topics as contract

if TYPE_CHECKING:
    from conveyor_twin.ros.run_recording import RecordingOptions
from conveyor_twin.record.writer import Compression


def add_writer_arguments(group: Any, prefix: str = '') -> None:
    """Add the MCAP writer's options (decimation, compression, flush period, queue size) to
    an argparse parser or group, named ``--<prefix>decimate`` etc. (``record`` uses no prefix,
    ``run --record`` the prefix ``record-``)."""
    group.add_argument(f'--{prefix}decimate', nargs='+', default=[], metavar='NAME=K',
                       help='record every K-th message of a topic, e.g. parts=10 density=100')
    group.add_argument(f'--{prefix}compression', default=Compression.LZ4.value,
                       choices=[c.value for c in Compression])
    group.add_argument(f'--{prefix}flush-period', type=float, default=0.1,
                       help='longest wall time between chunk flushes [s] (bounds a kill loss)')
    group.add_argument(f'--{prefix}queue-size', type=int, default=20000,
                       help='bound of the queue to the writer thread [messages]')


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``record``."""
    p = argparse.ArgumentParser(prog='conveyor-twin record', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('-o', '--output', required=True, help='MCAP file to write (overwritten)')
    p.add_argument('--namespace', default='', help="namespace of the twin's topics")
    p.add_argument('--topics', nargs='+', default=None, metavar='NAME',
                   help='contract topics to record (default: all but markers): '
                   + ', '.join(TOPICS))
    p.add_argument('--markers', action='store_true', help='record markers too')
    p.add_argument('--discover', action='store_true',
                   help='also record graph topics under the namespace with a known type')
    add_writer_arguments(p)
    p.add_argument('--duration', type=float, default=0.0,
                   help='stop after this wall time [s] (0: until SIGINT/SIGTERM)')
    p.add_argument('--json', action='store_true', help='print the summary as one JSON object')
    return p


def add_recording_arguments(p: argparse.ArgumentParser) -> None:
    """Add ``--record`` and its options (as ``conveyor-twin record`` has them) and
    ``--command`` to the parser of ``run``."""
    g = p.add_argument_group('recording (composed layout)')
    g.add_argument('--record', default=None, metavar='FILE.mcap',
                   help='record every stream, /clock, markers, diagnostics and the accepted '
                   'commands in-process to this MCAP file (overwritten)')
    g.add_argument('--record-topics', nargs='+', default=None, metavar='NAME',
                   help='record only these contract topics (default: every published one): '
                   + ', '.join(n for n, s in TOPICS.items() if not s.command))
    add_writer_arguments(g, prefix='record-')
    g.add_argument('--command', nargs='+', default=[], metavar='STEP:KIND:NAME=VALUE',
                   help='apply a command at a step, e.g. 500:belt:main=0.2 '
                   '1200:actuator:pusher=0.05 (validated like belt_command/actuator_command)')


def recording_options(args: argparse.Namespace) -> 'RecordingOptions':
    """Return ``run``'s parsed recording options (those of :func:`add_recording_arguments`,
    ``--cell`` and ``--markers-rate``) as a
    :class:`~conveyor_twin.ros.run_recording.RecordingOptions`."""
    from conveyor_twin.ros.run_recording import RecordingOptions

    return RecordingOptions(
        path=args.record, topics=args.record_topics, decimate=list(args.record_decimate),
        compression=args.record_compression, flush_period=args.record_flush_period,
        queue_size=args.record_queue_size, commands=list(args.command),
        cell_file=args.cell, markers_rate=args.markers_rate)


def main(argv: Optional[List[str]] = None) -> int:
    """Record until the duration ends, SIGINT/SIGTERM or a failure of the writer thread; print
    the summary; return 0, 1 if the file cannot be created, 2 for bad options, or
    :data:`~conveyor_twin.health.EXIT_BACKGROUND_FAILURE` if the writer failed (reported at
    once with its traceback)."""
    args = build_parser().parse_args(argv)
    from conveyor_twin.ros.record_node import parse_decimation, record, RecordOptions

    try:
        specs = contract.select(args.topics, markers=args.markers)
        decimation = parse_decimation(args.decimate, args.namespace)
    except (KeyError, ValueError) as err:
        print(f'conveyor-twin record: {err.args[0]}', file=sys.stderr)
        return 2
    return record(RecordOptions(
        output=args.output, specs=specs, decimation=decimation, namespace=args.namespace,
        discover=args.discover, compression=args.compression, flush_period=args.flush_period,
        queue_size=args.queue_size, duration=args.duration, json=args.json))


if __name__ == '__main__':
    sys.exit(main())
