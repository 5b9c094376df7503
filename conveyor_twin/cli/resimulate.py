"""``conveyor-twin resimulate FILE``: re-run a recording and compare every message bit for bit.

Rebuilds the cell from the recording (attachment ``cell.yaml``, seed, step, namespace, markers
rate), applies the recorded accepted commands at their steps, steps the twin's cores in this
process (no ROS: nothing is published) and compares every recorded stream message with the
bytes of the re-run's frames. Exit code 0: identical; 1: the first
difference is printed (topic, message number, step, byte offset, field); 2: the recording
cannot be re-simulated (the message says why).
"""

import argparse
import json
import os
import sys
from typing import List, Optional

from conveyor_twin.record.errors import RecordingError


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``resimulate``."""
    p = argparse.ArgumentParser(prog='conveyor-twin resimulate', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', help='recording made by conveyor-twin run --record')
    p.add_argument('--json', action='store_true', help='print the report as one JSON object')
    return p


def format_report(r: dict) -> str:
    """Return a report (``ResimReport.as_dict()``) as text."""
    head = (f"resimulated {r['path']}: {r['steps']} steps, {r['commands']} recorded commands "
            f"applied, {r.get('faults', 0)} recorded faults injected, "
            f"{r['compared_total']} messages compared")
    lines = [head]
    for topic, n in sorted(r['compared'].items()):
        lines.append(f'  {topic}: {n} identical')
    for topic, n in sorted(r['not_compared'].items()):
        lines.append(f'  {topic}: {n} not compared (wall-clock content)')
    if not r['complete_source']:
        lines.append('  (the recording has no footer: compared what a linear read recovers)')
    if r['ok']:
        lines.append('identical: every compared message matches bit for bit')
    else:
        lines.append(f"FIRST DIFFERENCE: {r['difference']['text']}")
    return '\n'.join(lines)


def main(argv: Optional[List[str]] = None) -> int:
    """Re-simulate and compare; return 0 (identical), 1 (difference) or 2 (cannot)."""
    args = build_parser().parse_args(argv)
    if not os.path.isfile(args.file):
        print(f'conveyor-twin resimulate: {args.file}: no such file', file=sys.stderr)
        return 2
    from conveyor_twin.record.resimulate import resimulate

    try:
        report = resimulate(args.file).as_dict()
    except RecordingError as exc:
        print(f'conveyor-twin resimulate: {exc}', file=sys.stderr)
        return 2
    print(json.dumps(report, sort_keys=True) if args.json else format_report(report))
    return 0 if report['ok'] else 1
