"""``conveyor-twin validate CELL.yaml``: exit 0 with a summary, 1 with the first error."""

import argparse
import sys
from typing import List

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.cell.summary import summarize


def main(argv: List[str]) -> int:
    """Validate a cell file (or the embedded default with no argument)."""
    parser = argparse.ArgumentParser(prog='conveyor-twin validate', description=__doc__)
    parser.add_argument('cell', nargs='?', default='',
                        help='cell YAML file (default: the embedded default cell)')
    args = parser.parse_args(argv)
    try:
        cell = load_cell(args.cell)
    except CellError as exc:
        print(f'invalid cell: {exc}', file=sys.stderr)
        return 1
    print(summarize(cell))
    target = args.cell or 'default'
    print(f'Draw it: conveyor-twin plot {target} -o cell.png')
    return 0
