"""Rewrite build-machine paths in the CMake files exported by the ROS 2 PyPI wheels.

The message wheels (``ros-std-msgs``, ...) export CMake targets that name the include directories
of the machine they were built on (``/opt/python/cp311-cp311/...`` in the cp311 wheels,
``/opt/python/cp312-cp312/...`` in the cp312 ones; Jazzy's and Kilted's alike). CMake's generate
step rejects imported targets with non-existent include paths, so ``msg_defs/`` cannot be
configured against an unpatched environment. This script replaces those paths with the running
interpreter's own Python and NumPy include directories. Run it with the environment's
interpreter; it is idempotent.
"""

import os
from pathlib import Path
import re
import sys
import sysconfig
from typing import Iterator, List, Pattern, Tuple

import numpy

# The build machine's interpreter prefix, e.g. /opt/python/cp312-cp312.
BUILD_PREFIX = r'/opt/python/cp3\d+-cp3\d+'
BUILD_NUMPY_INCLUDE = re.compile(
    BUILD_PREFIX + r'/lib/python3\.\d+/site-packages/numpy/(?:_core|core)/include')
BUILD_PYTHON_INCLUDE = re.compile(BUILD_PREFIX + r'/include/python3\.\d+')


def replacements() -> List[Tuple[Pattern, str]]:
    """Return the (build-machine path pattern, local path) pairs for this interpreter."""
    return [
        # The NumPy path first: it starts with the interpreter prefix too.
        (BUILD_NUMPY_INCLUDE, numpy.get_include()),
        (BUILD_PYTHON_INCLUDE, sysconfig.get_paths()['include']),
    ]


def cmake_files(prefix: Path) -> Iterator[Path]:
    """Yield the CMake files the wheels install under an environment prefix.

    The wheels put their ``share/<pkg>/cmake`` trees at ``<prefix>/share`` (wheel data), a few
    ``lib/cmake`` trees at ``<prefix>/lib/cmake``; site-packages is searched too, in case a wheel
    ships CMake files inside its Python package.

    :param prefix: environment prefix (``sys.prefix`` of the venv)
    :return: iterator over ``*.cmake`` files
    """
    site_packages = Path(sysconfig.get_paths()['purelib'])
    for root in (prefix / 'share', prefix / 'lib' / 'cmake', site_packages):
        if root.is_dir():
            yield from root.rglob('*.cmake')


def patch(prefix: Path) -> List[Path]:
    """Patch every CMake file below ``prefix`` in place; return the files changed.

    :param prefix: environment prefix
    :return: paths of the files that were rewritten
    """
    changed = []
    mapping = replacements()
    for path in cmake_files(prefix):
        text = path.read_text(encoding='utf-8', errors='surrogateescape')
        if not any(pattern.search(text) for pattern, _ in mapping):
            continue
        for pattern, local in mapping:
            text = pattern.sub(lambda _match, local=local: local, text)
        tmp = path.with_name(path.name + '.tmp')
        tmp.write_text(text, encoding='utf-8', errors='surrogateescape')
        os.replace(tmp, path)
        changed.append(path)
    return changed


def main() -> int:
    """Patch the running interpreter's environment and report how many files changed."""
    python_header = Path(sysconfig.get_paths()['include']) / 'Python.h'
    if not python_header.is_file():
        version = f'{sys.version_info[0]}.{sys.version_info[1]}'
        print(f'setup: error: {python_header} is missing: install the Python development '
              f'headers (e.g. python{version}-dev)', file=sys.stderr)
        return 1
    prefix = Path(sys.prefix)
    changed = patch(prefix)
    print(f'setup: patched build-machine paths in {len(changed)} CMake file(s) under {prefix}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
