"""``conveyor-twin plc-map [CELL.yaml]``: a cell's PLC tags, OPC UA paths and Modbus addresses."""

import argparse
from pathlib import Path
import sys
from typing import List

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.plc.tags import tag_map


def main(argv: List[str]) -> int:
    """Print (or write) the tag map of a cell (the embedded default cell with no argument)."""
    parser = argparse.ArgumentParser(prog='conveyor-twin plc-map', description=__doc__)
    parser.add_argument('cell', nargs='?', default='',
                        help='cell YAML file (default: the embedded default cell)')
    parser.add_argument('--format', choices=('markdown', 'csv'), default='markdown',
                        help='table format (default: markdown)')
    parser.add_argument('--output', '-o', default='',
                        help='write the table to this file instead of standard output')
    args = parser.parse_args(argv)
    try:
        cell = load_cell(args.cell)
    except CellError as exc:
        print(f'invalid cell: {exc}', file=sys.stderr)
        return 1
    tags = tag_map(cell)
    text = tags.to_csv() if args.format == 'csv' else tags.to_markdown()
    if not args.output:
        sys.stdout.write(text)
        return 0
    try:
        Path(args.output).write_text(text, encoding='utf-8')
    except OSError as exc:
        print(f'plc-map: cannot write {args.output}: {exc.strerror or exc}', file=sys.stderr)
        return 1
    print(f'wrote {len(tags.tags)} tags of cell {cell.settings.name!r} to {args.output}')
    return 0
