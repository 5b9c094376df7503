"""The kernels' numba cache: where it is, when it is dropped, and the notice while they compile."""

import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import textwrap

import pytest

from conveyor_twin import numba_cache

PACKAGE = Path(numba_cache.__file__).resolve().parent
RUN_TIMEOUT = 600.0  # [s]: a kernel compile on a loaded machine
NOTICE = 'compiling the simulation kernels'


def _tree(root):
    for package in numba_cache.KERNEL_PACKAGES:
        (root / package).mkdir(parents=True)
        (root / package / 'kernel.py').write_text(f'# {package}\n')
    for module in numba_cache.KERNEL_MODULES:
        (root / module).parent.mkdir(parents=True, exist_ok=True)
        (root / module).write_text(f'# {module}\n')


@pytest.fixture
def tree(tmp_path, monkeypatch):
    """A package tree of kernel sources, its cache root and a NUMBA_CACHE_DIR, all empty."""
    root, cache, user = tmp_path / 'pkg', tmp_path / 'cache', tmp_path / 'user'
    monkeypatch.setattr(numba_cache, '_ROOT', root)
    monkeypatch.setattr(numba_cache, 'cache_root', lambda: cache)
    monkeypatch.setattr(numba_cache, '_user_cache_dir', lambda: str(user))
    _tree(root)
    return root


def _fill(directories):
    for directory in directories:
        directory.mkdir(parents=True, exist_ok=True)
        for name in ('solver.advance-70.py311.nbi', 'solver.advance-70.py311.1.nbc'):
            (directory / name).write_bytes(b'x')


def _caches(root):
    return sorted(p.relative_to(root.parent).as_posix() for p in root.parent.rglob('*.nb?'))


def test_every_module_with_kernels_is_in_the_digest():
    imports_numba = re.compile(r'^\s*(from numba\b|import numba\b)', re.MULTILINE)
    with_kernels = {p for p in PACKAGE.rglob('*.py') if imports_numba.search(p.read_text())}
    with_kernels -= {PACKAGE / 'numba_cache.py', PACKAGE / 'cli' / 'warm_up.py'}
    assert with_kernels and with_kernels <= set(numba_cache.kernel_sources())


def test_a_change_in_any_kernel_source_drops_every_cache_of_the_kernels(tree):
    numba_cache.drop_stale_caches()  # first look: stores the stamp
    dirs = list(numba_cache.cache_dirs())
    assert len(dirs) == 3 * (len(numba_cache.KERNEL_PACKAGES) + len(numba_cache.KERNEL_MODULES))
    _fill(dirs)
    numba_cache.drop_stale_caches()  # nothing changed: every cache kept
    assert len(_caches(tree)) == 2 * len(dirs)
    (tree / 'macro' / 'kernel.py').write_text('# macro, edited\n')  # a callee only
    numba_cache.drop_stale_caches()
    assert _caches(tree) == []
    _fill(dirs[:1])
    numba_cache.drop_stale_caches()  # the new sources are the stamp now
    assert len(_caches(tree)) == 2


@pytest.mark.parametrize('edited', ['micro/contacts/response.py', 'plant/geometry.py'])
def test_a_change_in_a_sub_package_or_a_kernel_module_drops_them_all(tree, edited):
    (tree / 'micro' / 'contacts').mkdir()
    (tree / 'micro' / 'contacts' / 'response.py').write_text('# response\n')
    numba_cache.drop_stale_caches()
    _fill(numba_cache.cache_dirs())
    numba_cache.drop_stale_caches()
    assert any('contacts' in c for c in _caches(tree))
    (tree / edited).write_text('# edited\n')
    numba_cache.drop_stale_caches()
    assert _caches(tree) == []


def test_a_file_outside_the_kernels_changes_nothing(tree):
    numba_cache.drop_stale_caches()
    _fill(numba_cache.cache_dirs())
    before = _caches(tree)
    (tree / 'cli.py').write_text('# not a kernel\n')
    numba_cache.drop_stale_caches()
    assert _caches(tree) == before


def _cache_state(cache: Path) -> tuple:
    stamp = cache / numba_cache._STAMP
    return (stamp.read_text() if stamp.exists() else None,
            sorted(p.relative_to(cache).as_posix() for p in cache.rglob('*.nb?')))


def test_a_copy_of_the_tree_run_with_this_environment_keeps_apart_from_its_cache(tmp_path):
    copy = tmp_path / 'copy'
    shutil.copytree(PACKAGE, copy / 'conveyor_twin',
                    ignore=shutil.ignore_patterns('__pycache__'))
    kernel = copy / 'conveyor_twin' / 'micro' / 'drive.py'
    kernel.write_text(kernel.read_text() + '\n# edited in the copy\n')
    ours = numba_cache.cache_root()
    numba_cache.drop_stale_caches()   # this tree's stamp is current
    before = _cache_state(ours)
    environment = {k: v for k, v in os.environ.items() if not k.startswith('NUMBA_')}
    environment['PYTHONPATH'] = str(copy)
    result = subprocess.run(
        [sys.executable, '-c', 'import conveyor_twin.numba_cache as nc\n'
         'print(nc.cache_root())\nprint(nc.__file__)'], cwd=str(copy), capture_output=True,
        text=True, timeout=RUN_TIMEOUT, stdin=subprocess.DEVNULL, env=environment)
    assert result.returncode == 0, result.stderr[-4000:]
    theirs, module = (Path(line) for line in result.stdout.split())
    try:
        assert module.is_relative_to(copy)
        assert theirs != ours and theirs.parent == ours.parent
        # the copy's stamp is its own; this tree's stamp and kernels are untouched (they were
        # dropped before: a copy with other sources wiped the environment's one cache)
        assert (theirs / numba_cache._STAMP).exists()
        assert _cache_state(ours) == before
    finally:
        shutil.rmtree(theirs, ignore_errors=True)


def _python(code: str, cache: Path, first: str = '', **env: str) -> subprocess.CompletedProcess:
    """Run ``first``, then ``code`` in a fresh interpreter whose package cache root is ``cache``."""
    prelude = first + textwrap.dedent(f'''
        from pathlib import Path
        import conveyor_twin.numba_cache as nc
        nc.cache_root = lambda: Path({str(cache)!r})
    ''')
    environment = {k: v for k, v in os.environ.items()
                   if not k.startswith('NUMBA_')}
    environment.update(env)
    result = subprocess.run([sys.executable, '-c', prelude + textwrap.dedent(code)],
                            capture_output=True, text=True, timeout=RUN_TIMEOUT,
                            stdin=subprocess.DEVNULL, env=environment)
    assert result.returncode == 0, result.stderr[-4000:]
    return result


RAMP = '''
    import numpy as np
    from conveyor_twin.micro import drive
    drive.ramp(np.zeros(2), np.ones(2), np.full(2, 0.5))
    stats = drive.ramp.stats
    print('path', drive.ramp._cache._cache_path)
    print('hits', sum(stats.cache_hits.values()), 'misses', sum(stats.cache_misses.values()))
'''


def test_a_miss_compiles_into_the_cache_root_with_one_notice_and_a_hit_prints_nothing(tmp_path):
    cache = tmp_path / 'cache'
    first = _python(RAMP, cache)
    assert f'path {cache / "micro"}' in first.stdout
    assert 'hits 0 misses 1' in first.stdout
    assert first.stderr.count(NOTICE) == 1, first.stderr
    assert re.search(r'\.\.\. done in \d+\.\d s', first.stderr), first.stderr
    assert list((cache / 'micro').glob('drive.ramp-*.nbi'))
    second = _python(RAMP, cache)
    assert 'hits 1 misses 0' in second.stdout
    assert NOTICE not in second.stderr and 'done in' not in second.stderr, second.stderr


def test_numba_imported_first_still_caches_the_kernels_in_the_cache_root(tmp_path):
    user_module = tmp_path / 'mine.py'
    user_module.write_text('from numba import njit\n\n\n@njit(cache=True)\ndef f(x):\n'
                           '    return x\n')
    code = f'''
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        import mine
        from conveyor_twin.micro import drive
        print('package', drive.ramp._cache._cache_path)
        print('user', mine.f._cache._cache_path)
    '''
    cache = tmp_path / 'cache'
    result = _python(code, cache, first='import numba\n')
    assert f'package {cache / "micro"}\n' in result.stdout
    assert f'user {tmp_path / "__pycache__"}\n' in result.stdout  # numba's own place


def test_numba_cache_dir_wins(tmp_path):
    user = tmp_path / 'numba'
    result = _python('from conveyor_twin.micro import drive\n'
                     'print("package", drive.ramp._cache._cache_path)\n',
                     tmp_path / 'cache', NUMBA_CACHE_DIR=str(user))
    assert f'package {user}' in result.stdout
