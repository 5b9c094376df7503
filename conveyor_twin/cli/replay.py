"""``conveyor-twin replay FILE``: republish a recording with its original timing.

Every selected message is published as the recorded CDR bytes (``Publisher.publish(bytes)``,
no decoding), in log-time order, at ``t0 + (log_time - first_log_time) / rate`` on the
monotonic clock: absolute deadlines, so errors do not accumulate (sleep until
:data:`SPIN_MARGIN` before a deadline, then a short busy wait, as the twin's own pacer does).
Messages of one log time go out back to back. A late message is published at once and counted,
never skipped.

``/clock`` is the recording's ``/clock`` when it has one; otherwise it is synthesised from the
log times (one Clock before the first message of each new log time). Each topic is offered with
the QoS stored in the recording (``offered_qos_profiles``, first profile), else the contract's
for its type. The accepted commands (``/conveyor_twin/accepted/...``) are not republished
unless asked (``--accepted-as-commands``, which publishes them on the command topics, at their
effective time, to drive a live twin); the recorded command topics of a standalone recording
(``belt_command``, ``actuator_command``) are republished like any topic, so drop them with
``--topics`` when a live twin listens.

To catch the first messages, start the subscribers first and use ``--wait-for-subscribers``
with a ``--delay``: a publisher sees its subscribers match a moment before they see it, and a
message sent in between is lost even on a reliable topic (observed with Fast DDS 3.2, volatile
durability; 0.5 s was ample here).

With ``--loop``, the recording starts over after its last message plus one recorded spacing;
``/clock`` then jumps back, as with ``ros2 bag play --loop``.
"""
import argparse
import sys
from typing import List, Optional


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``replay``."""
    p = argparse.ArgumentParser(prog='conveyor-twin replay', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', help='MCAP recording')
    p.add_argument('--rate', type=float, default=1.0, help='speed factor (2: twice as fast)')
    p.add_argument('--loop', action='store_true', help='start over at the end until Ctrl-C')
    p.add_argument('--start-offset', type=float, default=0.0,
                   help='skip this much recorded time from the start [s]')
    p.add_argument('--topics', nargs='+', default=None, metavar='NAME',
                   help='topics to replay (default: all but the accepted commands)')
    p.add_argument('--no-clock', action='store_true', help='do not publish /clock')
    p.add_argument('--accepted-as-commands', action='store_true',
                   help='publish the accepted commands on belt_command/actuator_command')
    p.add_argument('--namespace', default='',
                   help='namespace of the command topics for --accepted-as-commands')
    p.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='TIMEOUT',
                   help='before starting, wait up to TIMEOUT [s] until every topic has a '
                   'subscriber')
    p.add_argument('--delay', type=float, default=0.0,
                   help='wait this long before the first message (after matching) [s]')
    p.add_argument('--linger', type=float, default=5.0, metavar='SECONDS',
                   help='at the end, wait up to this long until reliable subscribers have '
                   'acknowledged every message [s]')
    p.add_argument('--json', action='store_true', help='print the summary as one JSON object')
    return p


def main(argv: Optional[List[str]] = None) -> int:
    """Replay a recording; return 0, or 1 if it cannot be read, 2 on bad options,
    :data:`~conveyor_twin.health.EXIT_BACKGROUND_FAILURE` if the read-ahead thread failed
    otherwise (reported with its traceback)."""
    args = build_parser().parse_args(argv)
    if not args.rate > 0 or args.start_offset < 0:
        print('conveyor-twin replay: --rate must be > 0 and --start-offset >= 0',
              file=sys.stderr)
        return 2
    from conveyor_twin.ros.replay import replay, ReplayOptions

    return replay(ReplayOptions(
        file=args.file, rate=args.rate, loop=args.loop, start_offset=args.start_offset,
        topics=args.topics, clock=not args.no_clock,
        accepted_as_commands=args.accepted_as_commands, namespace=args.namespace,
        wait_for_subscribers=args.wait_for_subscribers, delay=args.delay, linger=args.linger,
        json=args.json))


if __name__ == '__main__':
    sys.exit(main())
