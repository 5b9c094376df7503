"""``conveyor-twin recover FILE [-o OUT]``: rebuild a killed, truncated or damaged recording.

Copies every intact chunk of FILE (schemas, channels, metadata, the cell attachment, messages)
into a new, indexed file OUT (default: ``FILE`` with ``.recovered.mcap``) and says what it kept:
messages per topic, the last recovered log time, chunks skipped as damaged and where and why
the scan stopped. What a killed recorder had not flushed yet is not in the file, so it cannot
be counted; with the default flush period that is at most ~0.1 s of wall time.

Exit codes:

- 0: FILE was complete and intact; OUT holds all of it.
- 3: partial: FILE was not closed (killed recorder, truncated copy) or had damaged chunks; OUT
  holds the intact part.
- 1: unreadable: FILE cannot be read, is not MCAP, or is damaged and holds no intact message
  at all (OUT is removed); also when OUT cannot be written.
"""

import argparse
import json
import os
import sys
from typing import List

from conveyor_twin.record import reader
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.writer import Compression

COMPLETE, UNREADABLE, PARTIAL = 0, 1, 3


def default_output(path: str) -> str:
    """Return ``name.recovered.mcap`` next to ``name.mcap``."""
    stem = path[:-5] if path.endswith('.mcap') else path
    return stem + '.recovered.mcap'


def main(argv: List[str]) -> int:
    """Recover a recording; return 0 (complete), 3 (partial) or 1 (unreadable)."""
    p = argparse.ArgumentParser(prog='conveyor-twin recover', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', help='damaged MCAP recording')
    p.add_argument('-o', '--output', default=None, help='file to write (default: '
                   'FILE.recovered.mcap)')
    p.add_argument('--compression', default=Compression.LZ4.value,
                   choices=[c.value for c in Compression])
    p.add_argument('--json', action='store_true', help='print the report as one JSON object')
    args = p.parse_args(argv)
    out = args.output or default_output(args.file)
    try:
        report = reader.recover(args.file, out, compression=args.compression)
    except RecordingError as err:
        print(f'conveyor-twin recover: {err}', file=sys.stderr)
        return UNREADABLE
    intact = report.complete_source and not report.damaged and not report.orphaned
    if intact:
        code = COMPLETE
    elif report.total == 0:
        os.remove(out)
        code = UNREADABLE
    else:
        code = PARTIAL
    verdict = {COMPLETE: 'complete', PARTIAL: 'partial', UNREADABLE: 'unreadable'}[code]
    last = report.last_time
    if args.json:
        print(json.dumps({'source': report.source, 'output': out if code != UNREADABLE else None,
                          'result': verdict, 'exit_code': code, 'messages': report.messages,
                          'last_log_time_ns': last, 'damaged': report.damaged,
                          'orphaned': report.orphaned, 'stop_reason': report.stop_reason},
                         sort_keys=True))
        return code
    if code == UNREADABLE:
        print(f'{args.file}: no intact message to recover ({report.stop_reason}); nothing '
              'written', file=sys.stderr)
        return code
    size = os.path.getsize(args.file)
    up_to = f', up to log time {last / 1e9:.6f} s' if last is not None else ''
    print(f'{verdict}: recovered {report.total} messages into {out}{up_to}')
    print(f'  source: {size} bytes, {"closed" if report.complete_source else "not closed"}; '
          f'scan stopped: {report.stop_reason}')
    for topic, n in sorted(report.messages.items()):
        print(f'  {topic:<44}{n:>10}  last {report.last_log_time[topic] / 1e9:.6f} s')
    for damage in report.damaged:
        print(f'  lost (damaged chunk): {damage}')
    if report.orphaned:
        print(f'  lost: {report.orphaned} messages of channels whose definition is missing')
    if not report.complete_source:
        print('  lost: whatever the recorder had not flushed when it stopped (not countable)')
    return code


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
