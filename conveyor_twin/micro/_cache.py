"""Drop stale numba caches of this package.

numba's ``cache=True`` keys a function's cached machine code on its own file only, so a kernel
whose callees (in other modules) changed would keep running the old code. On import, the
sources of the package are hashed; when the hash differs from the last import's, the package's
cache files are removed and the new hash is stored.
"""

import hashlib
from pathlib import Path

_HERE = Path(__file__).resolve().parent
_STAMP = 'conveyor_twin_micro.stamp'


def drop_stale_caches() -> None:
    """Remove this package's numba cache files if any of its sources changed."""
    digest = hashlib.sha256()
    for path in sorted(_HERE.glob('*.py')):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    stamp = digest.hexdigest()
    cache = _HERE / '__pycache__'
    stamp_file = cache / _STAMP
    try:
        if stamp_file.read_text() == stamp:
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for pattern in ('*.nbi', '*.nbc'):
            for path in cache.glob(pattern):
                path.unlink(missing_ok=True)
        stamp_file.write_text(stamp)
    except OSError:
        # read-only install: numba falls back to its own cache locator
        pass
