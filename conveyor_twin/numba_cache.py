"""Drop stale numba caches of the simulation packages.

numba's ``cache=True`` keys a function's cached machine code on its own file only, so a kernel
whose callees live in other modules (``macro.solver.advance`` inlines ``macro.fluxes`` and
``macro.collision``; ``coupling.handover`` calls ``micro.sources``) would keep running the old code
after only the callees changed, e.g. after a ``git pull``. On import of ``conveyor_twin`` the
sources of the kernel packages (sub-packages included) are hashed together; when the hash
differs from the last import's, their cache files (sub-packages' too) are removed and the new
hash is stored.
"""

import hashlib
from pathlib import Path

_ROOT = Path(__file__).resolve().parent
# Packages with numba kernels (cache=True); one hash over all of them, as they call each other.
KERNEL_PACKAGES = ('micro', 'macro', 'coupling')
_STAMP = 'conveyor_twin_kernels.stamp'


def sources_digest() -> str:
    """Return the SHA-256 of the kernel packages' sources (names and bytes)."""
    digest = hashlib.sha256()
    for package in KERNEL_PACKAGES:
        root = _ROOT / package
        for path in sorted(root.rglob('*.py')):
            digest.update(f'{package}/{path.relative_to(root).as_posix()}'.encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def drop_stale_caches() -> None:
    """Remove the kernel packages' numba cache files if any of their sources changed."""
    stamp = sources_digest()
    stamp_file = _ROOT / '__pycache__' / _STAMP
    try:
        if stamp_file.read_text() == stamp:
            return
    except OSError:
        pass
    try:
        for package in KERNEL_PACKAGES:
            for cache in (_ROOT / package).rglob('__pycache__'):
                for pattern in ('*.nbi', '*.nbc'):
                    for path in cache.glob(pattern):
                        path.unlink(missing_ok=True)
        stamp_file.parent.mkdir(exist_ok=True)
        stamp_file.write_text(stamp)
    except OSError:
        # read-only install: numba falls back to its own cache locator
        pass
