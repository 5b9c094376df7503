"""``conveyor-twin foxglove-layout CELL.yaml|PLANT.yaml -o layout.json``: write the Foxglove
layout of a cell's (or a plant's) live view.

The layout names that cell's topics: its scene, one density grid per macro zone, its belts'
speeds, its light barriers, its diagnostics (a plant's: every cell's, in the plant frame).
Import it in Foxglove with *Layout*, *Import from file* (docs/foxglove.md). Without a file:
the default cell. A bad file exits with status 2.
"""

import argparse
import json
import sys
from typing import List

from conveyor_twin.cell.errors import CellError


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``foxglove-layout``."""
    p = argparse.ArgumentParser(prog='conveyor-twin foxglove-layout', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', nargs='?', default=None,
                   help='cell YAML, or plant YAML (a top-level "plant:" key); default: the '
                   'default cell')
    p.add_argument('-o', '--output', default='-', help='layout file to write (- : stdout)')
    p.add_argument('--namespace', default='',
                   help="a cell's ROS namespace, as run with it (default: none)")
    return p


def _is_plant(path: str) -> bool:
    import yaml
    try:
        with open(path, encoding='utf-8') as f:
            data = yaml.safe_load(f)
    except (OSError, yaml.YAMLError):
        return False  # the cell loader reports what is wrong with the file
    return isinstance(data, dict) and 'plant' in data


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin foxglove-layout``; return the exit code."""
    from conveyor_twin.viz.foxglove_layout import cell_layout, plant_layout
    args = build_parser().parse_args(argv)
    try:
        if args.file is not None and _is_plant(args.file):
            from conveyor_twin.plant.loader import load_plant
            layout = plant_layout(load_plant(args.file))
        else:
            from conveyor_twin.cell import load_cell
            layout = cell_layout(load_cell(args.file), args.namespace)
    except CellError as exc:
        print(f'conveyor-twin foxglove-layout: {exc}', file=sys.stderr)
        return 2
    text = json.dumps(layout, indent=2) + '\n'
    if args.output == '-':
        sys.stdout.write(text)
    else:
        try:
            with open(args.output, 'w', encoding='utf-8') as f:
                f.write(text)
        except OSError as exc:
            print(f'conveyor-twin foxglove-layout: -o {args.output}: {exc}', file=sys.stderr)
            return 2
        print(f'conveyor-twin foxglove-layout: wrote {args.output}', file=sys.stderr)
    return 0
