"""``conveyor-twin warm-up`` fills the kernel cache: a run after it compiles nothing.

Each test starts from an empty cache (``NUMBA_CACHE_DIR`` in a temporary directory), so it
compiles the kernels once (tens of seconds). Compiles are counted from numba's own cache log
(``NUMBA_DEBUG_CACHE``: one ``data saved`` line per compiled signature), never timed.
"""

from pathlib import Path
import re
import subprocess
import sys
from typing import Dict

import pytest

from conveyor_twin.cli.warm_up import shipped_cells
from conveyor_twin.testing import ros_subprocess_env

pytestmark = [pytest.mark.slow]
RUN_TIMEOUT = 900.0  # [s]: compiling every kernel on a loaded machine
DEFAULT_CELL = Path(shipped_cells()[0])
NOTICE = 'compiling the simulation kernels'


def _cli(cache: Path, *args: str) -> subprocess.CompletedProcess:
    env: Dict[str, str] = ros_subprocess_env({'NUMBA_CACHE_DIR': str(cache),
                                              'NUMBA_DEBUG_CACHE': '1'})
    result = subprocess.run([sys.executable, '-m', 'conveyor_twin.cli', *args],
                            capture_output=True, text=True, timeout=RUN_TIMEOUT,
                            stdin=subprocess.DEVNULL, env=env, cwd=cache.parent)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result


def _compiled(result: subprocess.CompletedProcess) -> int:
    return len(re.findall(r'^\[cache\] data saved', result.stdout + result.stderr, re.MULTILINE))


def test_the_default_cell_is_shipped_and_first():
    assert DEFAULT_CELL.name == 'default_cell.yaml'
    assert {p.parent.name for p in shipped_cells()} == {'cell', 'examples'}


@pytest.mark.ros
def test_after_warm_up_a_run_compiles_nothing(tmp_path):
    cache = tmp_path / 'numba'
    first = _cli(cache, 'warm-up', str(DEFAULT_CELL))
    assert _compiled(first) > 10
    assert NOTICE not in first.stderr  # the command reports by itself
    assert re.search(r'warm-up: \d+ kernels, 1 cells .* [1-9]\d* signatures compiled',
                     first.stdout), first.stdout
    again = _cli(cache, 'warm-up', str(DEFAULT_CELL))
    assert _compiled(again) == 0
    assert re.search(r' 0 signatures compiled, [1-9]\d* loaded', again.stdout), again.stdout
    run = _cli(cache, 'run', '--mode', 'fast', '--duration', '0.2', '--markers-rate', '0')
    assert _compiled(run) == 0, run.stderr[-3000:]
    assert NOTICE not in run.stderr
    assert 'data loaded' in run.stdout + run.stderr


def test_a_warm_up_on_an_empty_cache_says_once_that_it_compiles(tmp_path):
    # the notice ends a series of compiles after QUIET_AFTER s without one; a long pause here
    # keeps a loaded machine's gaps between compiles from splitting the series
    code = ('import conveyor_twin.numba_cache as nc\n'
            'nc.QUIET_AFTER = 600.0\n'
            'from conveyor_twin.cell import load_cell\n'
            'from conveyor_twin.coord.warmup import warm_up\n'
            f'warm_up(load_cell({str(DEFAULT_CELL)!r}), 1, steps=5)\n')
    env = ros_subprocess_env({'NUMBA_CACHE_DIR': str(tmp_path / 'numba')})
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=RUN_TIMEOUT, stdin=subprocess.DEVNULL, env=env)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stderr.count(NOTICE) == 1, result.stderr
    assert result.stderr.count('... done in') == 1, result.stderr


# After the warm-up, a twin of a cell with an ``auto`` zone switches its tiles to macro and
# back; prints every kernel that gained a signature meanwhile (loaded or compiled at that use).
FIRST_SWITCH = '''
import sys
import numpy as np
from numba.core.registry import CPUDispatcher
from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.warmup import warm_up

def signatures():
    return {f'{d.py_func.__module__}.{d.py_func.__qualname__}': len(d.signatures)
            for name, mod in list(sys.modules.items()) if name.startswith('conveyor_twin')
            for d in vars(mod).values() if isinstance(d, CPUDispatcher)}

cell = load_cell(sys.argv[1])
warm_up(cell, 1)
before = signatures()
built = build_twin(cell, seed=1)
for _ in range(300):
    built.twin.step(1)
[region] = [r for r in built.coupling.regions if r.tiles is not None]
for macro in (np.ones_like(region.tiles.macro), np.zeros_like(region.tiles.macro)):
    built.coupling.force_tiles(region.sim.zone.name, macro)
    for _ in range(20):
        built.twin.step(1)
after = signatures()
print('captured', built.coupling.captured)
print('loaded', sorted(k for k in after if after[k] != before.get(k, 0)))
'''


def test_after_warm_up_the_first_switch_of_an_auto_zone_loads_no_kernel():
    cell = DEFAULT_CELL.parent / 'examples' / 'l_line.yaml'
    result = subprocess.run([sys.executable, '-c', FIRST_SWITCH, str(cell)],
                            capture_output=True, text=True, timeout=RUN_TIMEOUT,
                            stdin=subprocess.DEVNULL, env=ros_subprocess_env({}))
    assert result.returncode == 0, result.stderr[-3000:]
    # the switch took parts into the macro scale (the capture kernels ran), and every kernel
    # of the hand-over was loaded before the twin's first step
    assert re.search(r'^captured [1-9]', result.stdout, re.MULTILINE), result.stdout
    assert 'loaded []' in result.stdout, result.stdout
