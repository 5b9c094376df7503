"""``conveyor-twin info FILE``: summarize a recording like ``ros2 bag info``.

Topics with their types, message counts and rates, the recorded time span (simulation time),
the cell name, seed and step of the run, the chunk compression, and the recorder's counters
(decimated, dropped) when the recording was closed. A killed recording is summarized from its
intact chunks (``complete: no``). ``--json`` prints the summary as one JSON object.

Exit codes: 0 summarized, 1 the file cannot be read or is not MCAP.
"""

import argparse
import json
import sys
from typing import Any, Dict, List

from conveyor_twin.record import reader
from conveyor_twin.record.errors import RecordingError


def _size(n: int) -> str:
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if n < 1024 or unit == 'GiB':
            return f'{n:.1f} {unit}' if unit != 'B' else f'{n} B'
        n /= 1024
    return f'{n} B'


def format_info(s: Dict[str, Any]) -> str:
    """Return the summary of :func:`conveyor_twin.record.reader.info` as aligned text."""
    rows = [
        ('Files', s['path']),
        ('Bag size', _size(s['size'])),
        ('Storage id', f"mcap (profile {s['profile'] or '?'}, {s['library'] or '?'})"),
        ('Complete', 'yes' if s['complete'] else f"no ({s['stop_reason']})"),
        ('Duration', f"{s['duration_ns'] / 1e9:.9f} s"),
        ('Start', f"{s['start_ns'] / 1e9:.9f} s (log time: simulation time)"),
        ('End', f"{s['end_ns'] / 1e9:.9f} s"),
        ('Messages', str(s['message_count'])),
        ('Compression', f"{', '.join(s['compression']) or 'none'} ({s['chunk_count']} chunks)"),
        ('Cell', s['cell_name'] or '-'),
        ('Seed', '-' if s['seed'] is None else str(s['seed'])),
        ('Step', '-' if s['step_ns'] is None else f"{s['step_ns'] / 1e6:g} ms"),
        ('Attachments', ', '.join(s['attachments']) or '-'),
    ]
    width = max(len(k) for k, _ in rows) + 2
    lines = [f'{k + ":":<{width}}{v}' for k, v in rows]
    recorder = (s.get('recorder') or {}).get('topics', {})
    lines.append('Topic information:')
    name_w = max([len(t) for t in s['topics']] + [5])
    type_w = max([len(t['type']) for t in s['topics'].values()] + [4])
    for topic, t in s['topics'].items():
        extra = ''
        rec = recorder.get(topic)
        if rec and (rec.get('decimated') or rec.get('dropped')):
            extra = f" | Decimated: {rec['decimated']} | Dropped: {rec['dropped']}"
        lines.append(f"  Topic: {topic:<{name_w}} | Type: {t['type']:<{type_w}} | "
                     f"Count: {t['count']:>8} | Rate: {t['rate_hz']:9.2f} Hz | "
                     f'Serialization Format: cdr{extra}')
    for damage in s['damaged']:
        lines.append(f'Damaged: {damage}')
    return '\n'.join(lines)


def main(argv: List[str]) -> int:
    """Print the summary of a recording; return 0, or 1 if it cannot be read."""
    p = argparse.ArgumentParser(prog='conveyor-twin info', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', help='MCAP recording')
    p.add_argument('--json', action='store_true', help='print one JSON object')
    args = p.parse_args(argv)
    try:
        s = reader.info(args.file)
    except RecordingError as err:
        print(f'conveyor-twin info: {err}', file=sys.stderr)
        return 1
    print(json.dumps(s, sort_keys=True) if args.json else format_info(s))
    return 0
