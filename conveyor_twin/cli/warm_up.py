"""``conveyor-twin warm-up``: compile (or load) every numba kernel of the package, ahead of use.

Steps a scratch twin of every shipped cell (``conveyor_twin/cell/*.yaml`` and its
``examples/``, or the cells given) through the paths of a run
(:func:`conveyor_twin.coord.warmup.warm_up`: parts at every barrier, every actuator and belt
moving) and calls the plant's link kernel once, so that every kernel signature a composed or
split run, a plant cell or the testing fixture calls is in this environment's numba cache
(:func:`conveyor_twin.numba_cache.cache_root`) and the first run starts in seconds. Prints what
it did and how long it took. ``make setup`` runs it; with a valid cache it only loads (seconds).

Exit codes: 0 done; 1 a cell is invalid; 2 invalid options.
"""

import argparse
from pathlib import Path
import sys
import time
from typing import List, Tuple

import numpy as np

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.numba_cache import active_cache_dir, compile_notice

CELL_DIR = Path(__file__).resolve().parents[1] / 'cell'


def shipped_cells() -> List[Path]:
    """Return the cell files the package ships, default cell first."""
    files = sorted(CELL_DIR.glob('*.yaml')) + sorted((CELL_DIR / 'examples').glob('*.yaml'))
    return sorted(files, key=lambda p: p.name != 'default_cell.yaml')


def kernel_stats() -> Tuple[int, int, int]:
    """Return (kernels, signatures loaded from the cache, signatures compiled) of the package's
    numba kernels imported so far in this process."""
    from numba.core.registry import CPUDispatcher
    kernels, hits, misses = set(), 0, 0
    for name, module in list(sys.modules.items()):
        if not name.startswith('conveyor_twin.') or module is None:
            continue
        for value in list(vars(module).values()):
            if isinstance(value, CPUDispatcher) and id(value) not in kernels \
                    and value.__module__ == name:
                kernels.add(id(value))
                hits += sum(value.stats.cache_hits.values())
                misses += sum(value.stats.cache_misses.values())
    return len(kernels), hits, misses


def warm_up_plant() -> None:
    """Call the plant's link kernel with the argument types a plant cell passes it."""
    from conveyor_twin.plant.geometry import mark_inside
    x = np.zeros((2, 4))  # rows of the parts' state, as ``MicroState.P[0]``, ``P[1]``
    mark = np.zeros(4, dtype=np.bool_)
    mark_inside(0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.5, x[0], x[1], 1, 1 << 62, mark)


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``warm-up``."""
    p = argparse.ArgumentParser(prog='conveyor-twin warm-up', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('cells', nargs='*', metavar='CELL.yaml',
                   help='cells to warm up for (default: every shipped cell)')
    p.add_argument('--quiet', action='store_true', help='print only the summary line')
    return p


def main(argv: List[str]) -> int:
    """Run ``conveyor-twin warm-up``; return the exit code."""
    args = build_parser().parse_args(argv)
    compile_notice(False)  # this command reports by itself
    start = time.monotonic()
    files = [Path(f) for f in args.cells] or shipped_cells()
    try:
        cells = [(path, load_cell(str(path))) for path in files]
    except CellError as exc:
        print(f'conveyor-twin warm-up: invalid cell: {exc}', file=sys.stderr)
        return 1
    from conveyor_twin.coord.warmup import warm_up
    for path, cell in cells:
        before = time.monotonic()
        warm_up(cell, cell.settings.seed)
        if not args.quiet:
            kernels, hits, misses = kernel_stats()
            print(f'warm-up: {path.name}: {time.monotonic() - before:.1f} s '
                  f'(so far {misses} compiled, {hits} loaded)', flush=True)
    warm_up_plant()
    kernels, hits, misses = kernel_stats()
    print(f'warm-up: {kernels} kernels, {len(cells)} cells and the plant link in '
          f'{time.monotonic() - start:.1f} s: {misses} signatures compiled, {hits} loaded from '
          f'the cache with their callees (cache: {active_cache_dir()})')
    return 0
