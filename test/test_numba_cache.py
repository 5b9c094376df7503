"""Stale numba caches are dropped when any kernel package's source changes."""

from conveyor_twin import numba_cache


def _tree(root):
    for package in numba_cache.KERNEL_PACKAGES:
        (root / package / '__pycache__').mkdir(parents=True)
        (root / package / 'kernel.py').write_text(f'# {package}\n')


def _caches(root):
    return sorted(p.relative_to(root).as_posix() for p in root.glob('*/__pycache__/*.nb?'))


def test_a_change_in_one_package_drops_the_caches_of_all(tmp_path, monkeypatch):
    monkeypatch.setattr(numba_cache, '_ROOT', tmp_path)
    _tree(tmp_path)
    numba_cache.drop_stale_caches()  # first import: stores the stamp
    for package in numba_cache.KERNEL_PACKAGES:
        for name in ('solver.advance-70.py311.nbi', 'solver.advance-70.py311.1.nbc'):
            (tmp_path / package / '__pycache__' / name).write_bytes(b'x')
    numba_cache.drop_stale_caches()  # nothing changed: caches kept
    assert len(_caches(tmp_path)) == 6
    (tmp_path / 'macro' / 'kernel.py').write_text('# macro, edited\n')  # a callee only
    numba_cache.drop_stale_caches()
    assert _caches(tmp_path) == []
    (tmp_path / 'micro' / '__pycache__' / 'x.nbi').write_bytes(b'x')
    numba_cache.drop_stale_caches()  # the new sources are the stamp now
    assert _caches(tmp_path) == ['micro/__pycache__/x.nbi']


def test_a_change_in_a_sub_package_drops_its_caches_and_the_others(tmp_path, monkeypatch):
    monkeypatch.setattr(numba_cache, '_ROOT', tmp_path)
    _tree(tmp_path)
    sub = tmp_path / 'micro' / 'contacts'
    (sub / '__pycache__').mkdir(parents=True)
    (sub / 'response.py').write_text('# response\n')
    numba_cache.drop_stale_caches()
    (sub / '__pycache__' / 'response.solve-1.py311.nbi').write_bytes(b'x')
    (tmp_path / 'macro' / '__pycache__' / 'solver.advance-70.py311.nbi').write_bytes(b'x')
    numba_cache.drop_stale_caches()  # nothing changed: caches kept
    assert (sub / '__pycache__' / 'response.solve-1.py311.nbi').exists()
    (sub / 'response.py').write_text('# response, edited\n')
    numba_cache.drop_stale_caches()
    assert not (sub / '__pycache__' / 'response.solve-1.py311.nbi').exists()
    assert _caches(tmp_path) == []
