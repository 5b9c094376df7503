"""Where the package's numba kernels are cached, when that cache is stale, and a notice on a miss.

**Location.** numba by default writes a kernel's machine code to ``__pycache__`` beside its
source: for an editable install that is the source tree, shared by every environment built from
it, and for a wheel it is site-packages, which may be read-only. The kernels of this package are
cached per environment instead, in :func:`cache_root` = ``<sys.prefix>/var/cache/conveyor_twin/
numba/<tree>`` (a venv's prefix is the venv; ``<tree>`` names the package's source tree, so
two checkouts run with one environment keep apart caches), one directory per source directory
(``micro/contacts`` ...). It is the same for an editable and a wheel install, holds only what
this environment's numba, Python and CPU compiled, survives a reinstall of the package and goes
with the environment. ``conveyor-twin warm-up`` (``make setup`` runs it) fills it.

The place is given by a cache locator of this package, put first in numba's list of locators when
``numba.core.caching`` is imported (at once if it already is: a user may import numba before
this package); it answers only for this package's files, so the user's own kernels are cached
where numba would put them. numba reads ``NUMBA_CACHE_DIR`` at its import: when it is set, it
wins and the kernels are cached there. When the prefix is not writable, numba falls back to its
own locators (``__pycache__``, then the user's cache directory).

**Staleness.** numba keys a cached kernel on the SHA-256 of its own source file and numba's
version (0.68: content, not mtime, so a reinstall of unchanged sources keeps the cache), but a
kernel compiled from callees of other modules (``macro.solver.advance`` inlines ``macro.fluxes``;
``coupling.handover`` calls ``micro.sources``) and module constants (``micro.state``) would keep
the old code after only those changed. So on import of ``conveyor_twin`` the sources of every
kernel module are hashed together (:func:`sources_digest`); when the hash differs from the one
stored in the cache root, every cache file of the package's kernels (in the cache root, in
``__pycache__`` and under ``NUMBA_CACHE_DIR``) is removed and the new hash is stored.

**Notice.** A kernel that is not in the cache compiles on its first call (all of them: ~20 s).
That is announced once on stderr, when the first one starts, and its end with the time taken
once the compiles stop for :data:`QUIET_AFTER` s; a warm start loads from the cache and prints
nothing.
"""

import atexit
import hashlib
import importlib.abc
import importlib.machinery
import os
from pathlib import Path
import sys
import threading
import time
from typing import Iterator, List, Optional

_ROOT = Path(os.path.realpath(__file__)).parent
# Packages and modules with numba kernels (cache=True); one hash over all of them, as they call
# each other and read each other's constants. test/test_numba_cache.py checks that every module
# importing numba is among them.
KERNEL_PACKAGES = ('micro', 'macro', 'coupling')
KERNEL_MODULES = ('plant/geometry.py',)
_STAMP = 'conveyor_twin_kernels.stamp'
CACHE_PATTERNS = ('*.nbi', '*.nbc')
#: Seconds without a compile after which the notice says the compiling is done [s].
QUIET_AFTER = 1.0
#: What a first run compiles takes about this long (2-core machine, all kernels) [s].
COMPILE_ESTIMATE = 20


def tree_folder(root: Path) -> str:
    """Return the cache folder's name for the package's source tree at ``root``: two trees
    run with one environment (two checkouts, a copy on ``PYTHONPATH``) keep apart caches and
    stamps, so neither drops the other's kernels."""
    return f'{root.parent.name}-{hashlib.sha1(str(root).encode()).hexdigest()[:12]}'


def cache_root() -> Path:
    """Return this environment's cache directory of the kernels of this source tree."""
    return (Path(os.path.realpath(sys.prefix)) / 'var' / 'cache' / 'conveyor_twin' / 'numba'
            / tree_folder(_ROOT))


def active_cache_dir() -> Path:
    """Return where the kernels are cached now: ``NUMBA_CACHE_DIR`` if set, else
    :func:`cache_root` (numba's own fallbacks aside)."""
    return Path(_user_cache_dir()) if _user_cache_dir() else cache_root()


def kernel_sources() -> List[Path]:
    """Return the source files of the kernel packages and modules, sorted."""
    paths = [p for package in KERNEL_PACKAGES for p in (_ROOT / package).rglob('*.py')]
    paths += [_ROOT / module for module in KERNEL_MODULES]
    return sorted(paths)


def sources_digest() -> str:
    """Return the SHA-256 of the kernel sources (paths relative to the package, and bytes)."""
    digest = hashlib.sha256()
    for path in kernel_sources():
        digest.update(path.relative_to(_ROOT).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _user_cache_dir() -> str:
    if 'numba.core.config' in sys.modules:
        return sys.modules['numba.core.config'].CACHE_DIR or ''
    return os.environ.get('NUMBA_CACHE_DIR', '')


def _numba_subpath(directory: Path) -> str:
    # as numba's _CacheLocator.get_suitable_cache_subpath names a source directory's cache
    return f'{directory.name}_{hashlib.sha1(str(directory).encode()).hexdigest()}'


def cache_dirs() -> Iterator[Path]:
    """Yield every directory the kernels' cache files may be in (existing or not)."""
    user_dir = _user_cache_dir()
    directories = sorted({p.parent for p in kernel_sources()})
    for directory in directories:
        yield cache_root() / directory.relative_to(_ROOT)
        yield directory / '__pycache__'
        if user_dir:
            yield Path(user_dir) / _numba_subpath(directory)


def _stamp_file() -> Path:
    for candidate in (cache_root(), _ROOT / '__pycache__'):
        try:
            candidate.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        if os.access(candidate, os.W_OK):
            return candidate / _STAMP
    return cache_root() / _STAMP


def drop_stale_caches() -> None:
    """Remove the kernels' numba cache files if any kernel source changed since the last look."""
    stamp = sources_digest()
    stamp_file = _stamp_file()
    try:
        if stamp_file.read_text() == stamp:
            return
    except OSError:
        pass
    try:
        for cache in cache_dirs():
            for pattern in CACHE_PATTERNS:
                for path in cache.glob(pattern):
                    path.unlink(missing_ok=True)
        stamp_file.write_text(stamp)
    except OSError:
        pass  # read-only install: numba's own stamps still guard each kernel's own file


def _inside_package(py_file: str) -> bool:
    try:
        Path(os.path.realpath(py_file)).relative_to(_ROOT)
    except ValueError:
        return False
    return True


def _install(caching) -> None:
    """Put the package's locator first in numba's list (``caching``: numba.core.caching)."""
    try:
        _install_locator(caching)
    except (AttributeError, TypeError) as exc:  # numba's caching internals changed
        print(f'conveyor_twin: cannot place the kernel cache in {cache_root()} with this '
              f'numba ({exc!r}); numba caches the kernels where it does by default',
              file=sys.stderr)


def _install_locator(caching) -> None:
    impl = caching.CacheImpl
    if any(getattr(c, 'conveyor_twin', False) for c in impl._locator_classes):
        return

    class PackageCacheLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
        """Caches a kernel of this package in :func:`cache_root` (see the module)."""

        conveyor_twin = True

        def __init__(self, py_func, py_file: str) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            relative = Path(os.path.realpath(py_file)).parent.relative_to(_ROOT)
            self._cache_path = str(cache_root() / relative)

        def get_cache_path(self) -> str:
            return self._cache_path

        @classmethod
        def from_function(cls, py_func, py_file: str):
            if not _inside_package(py_file):
                return None
            _NOTICE.listen()
            if _user_cache_dir():
                return None  # NUMBA_CACHE_DIR wins
            return super().from_function(py_func, py_file)

    impl._locator_classes = [PackageCacheLocator, *impl._locator_classes]


class _AfterNumbaCaching(importlib.abc.MetaPathFinder):
    """Installs the locator right after ``numba.core.caching`` is executed (then leaves)."""

    def find_spec(self, name, path, target=None):
        if name != 'numba.core.caching':
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None:
            return spec
        exec_module = spec.loader.exec_module

        def exec_and_install(module) -> None:
            exec_module(module)
            _install(module)

        spec.loader.exec_module = exec_and_install
        return spec


def use_package_cache() -> None:
    """Cache the package's kernels in :func:`cache_root` (now, or when numba is imported)."""
    if 'numba.core.caching' in sys.modules:
        _install(sys.modules['numba.core.caching'])
    elif not any(isinstance(f, _AfterNumbaCaching) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaCaching())


class _CompileNotice:
    """One line on stderr when the package's kernels start compiling, one when they are done."""

    def __init__(self) -> None:
        self._listening = False
        self._depth = 0
        self._started: Optional[float] = None
        self._ended = 0.0
        self._timer: Optional[threading.Timer] = None
        self._lock = threading.Lock()
        self.enabled = True  # ``conveyor-twin warm-up`` reports by itself

    def listen(self) -> None:
        """Register with numba's compile events (once; numba is imported by then)."""
        if self._listening:
            return
        from numba.core import event
        self._listening = True
        listener = self

        class Listener(event.Listener):
            def on_start(self, ev) -> None:
                listener.on_start(ev.data['dispatcher'].py_func.__module__)

            def on_end(self, ev) -> None:
                listener.on_end()

        event.register('numba:compile', Listener())
        atexit.register(self.finish)

    def on_start(self, module: str) -> None:
        """A compile starts (numba holds its compiler lock)."""
        self._depth += 1
        if self._depth > 1 or not module.startswith('conveyor_twin.') or not self.enabled:
            return
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()  # the same series of compiles goes on
                self._timer = None
            elif self._started is None:
                self._started = time.monotonic()
                print(f'conveyor_twin: compiling the simulation kernels (first run after install '
                      f'or a change, ~{COMPILE_ESTIMATE} s; `conveyor-twin warm-up` does it '
                      f'ahead) ...', file=sys.stderr, flush=True)

    def on_end(self) -> None:
        """A compile ended: the series is done unless another one starts soon."""
        self._depth -= 1
        if self._depth > 0:
            return
        with self._lock:
            if self._started is None:
                return
            self._ended = time.monotonic()
            self._timer = threading.Timer(QUIET_AFTER, self.finish)
            self._timer.daemon = True
            self._timer.start()

    def finish(self) -> None:
        """Print the end of a series of compiles (if one is open)."""
        with self._lock:
            if self._started is None:
                return
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            took = max(self._ended, self._started) - self._started
            self._started = None
        print(f'conveyor_twin: ... done in {took:.1f} s (cached in {active_cache_dir()})',
              file=sys.stderr, flush=True)


_NOTICE = _CompileNotice()


def compile_notice(enabled: bool) -> None:
    """Turn the compile notice on stderr on or off (for this process)."""
    _NOTICE.enabled = enabled
