"""Assemble the binary wheel: the pure ``conveyor_twin`` wheel plus the built interface packages.

Layout of ``conveyor_twin-<version>+<distro>-cpXY-cpXY-manylinux_2_28_x86_64.whl``:

- ``conveyor_twin/``, ``conveyor_twin_msgs/``, ``simulation_interfaces/`` (Python modules and
  their extension modules) and ``conveyor_twin_ament_prefix.pth`` in site-packages;
- ``<name>.data/data/lib/lib<package>__*.so`` (typesupport libraries): pip installs them
  into ``<venv>/lib``, which ros-wheels-bootstrapper puts on ``LD_LIBRARY_PATH`` when the venv's
  python starts, as it does for the ROS wheels' own libraries;
- ``<name>.data/data/share/``: the ament index entries, ``package.xml`` and the interface files
  of the packages, and the cells; the ``.pth`` file puts the venv prefix on ``AMENT_PREFIX_PATH``
  at every start of its python, so ament index lookups find them with nothing sourced.

Headers and CMake files of the message package are left out: the wheel is for running the twin,
not for compiling against its messages.
"""

import base64
import csv
import hashlib
import io
from pathlib import Path
from typing import Dict, Iterator, List, Tuple
import zipfile

from .metadata import (EXTRAS, INTERFACE_PACKAGES, MESSAGE_PACKAGE, PLATFORM_TAG, requires_dist,
                       wheel_version)

NAME = 'conveyor_twin'
#: Same line as tools/setup_env.sh writes into a development environment.
PTH_NAME = 'conveyor_twin_ament_prefix.pth'
PTH_LINE = ('import os, sys; _p = os.environ.get("AMENT_PREFIX_PATH", ""); '
            'sys.prefix in _p.split(os.pathsep) or os.environ.__setitem__("AMENT_PREFIX_PATH", '
            'os.pathsep.join(filter(None, (sys.prefix, _p))))\n')
#: Fixed time stamp of every member, so the same inputs give the same bytes.
ZIP_TIME = (2020, 1, 1, 0, 0, 0)
#: ament index resources of the message package that go into the wheel (parent_prefix_path names
#: the build's AMENT_PREFIX_PATH, which means nothing on another machine).
INDEX_RESOURCES = ('packages', 'package_run_dependencies', 'rosidl_interfaces')


def message_files(stage: Path, python: str) -> Iterator[Tuple[str, Path]]:
    """Yield ``(path in the wheel, file)`` of every interface package installed into ``stage``
    (:data:`INTERFACE_PACKAGES`).

    :param python: ``X.Y`` of the interpreter they were built for.
    """
    for package in INTERFACE_PACKAGES:
        yield from _package_files(stage, python, package)


def _package_files(stage: Path, python: str, package: str) -> Iterator[Tuple[str, Path]]:
    data = f'{NAME}-{{version}}.data/data'
    site = stage / 'lib' / f'python{python}' / 'site-packages' / package
    if not site.is_dir():
        raise FileNotFoundError(f'{site} is missing: {package} was not built for '
                                f'Python {python}')
    for path in sorted(site.rglob('*')):
        if (path.is_file() and '__pycache__' not in path.parts
                and path.suffix not in ('.c', '.pyc')):
            yield f'{package}/{path.relative_to(site).as_posix()}', path
    libs = sorted((stage / 'lib').glob(f'lib{package}__*.so'))
    if not libs:
        raise FileNotFoundError(f'{stage}/lib has no lib{package}__*.so')
    for path in libs:
        yield f'{data}/lib/{path.name}', path
    index = stage / 'share' / 'ament_index' / 'resource_index'
    for resource in INDEX_RESOURCES:
        path = index / resource / package
        if path.is_file():
            yield f'{data}/share/ament_index/resource_index/{resource}/{package}', path
    share = stage / 'share' / package
    yield f'{data}/share/{package}/package.xml', share / 'package.xml'
    for sub in ('msg', 'srv', 'action'):
        for path in sorted((share / sub).glob('*')):
            if path.suffix in ('.msg', '.srv', '.action', '.idl', '.json'):
                yield f'{data}/share/{package}/{sub}/{path.name}', path


def _record_hash(data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b'=').decode()
    return f'sha256={digest}'


def _metadata(text: str, version: str, distro: str) -> str:
    """Return the pure wheel's METADATA with the binary wheel's version and dependencies."""
    head, _, body = text.partition('\n\n')
    lines = [line for line in head.splitlines()
             if not line.startswith(('Version:', 'Provides-Extra:'))]
    lines.insert(2, f'Version: {version}')
    lines += [f'Provides-Extra: {extra}' for extra in EXTRAS]
    lines += [f'Requires-Dist: {req}' for req in requires_dist(distro)]
    summary = (f'Built for ROS 2 {distro.capitalize()} from the PyPI wheels; includes the '
               f'message package {MESSAGE_PACKAGE} and simulation_interfaces.\n')
    return '\n'.join(lines) + '\n\n' + (body or summary)


def _wheel_file(tag: str) -> str:
    return ('Wheel-Version: 1.0\nGenerator: conveyor_twin tools/build_wheel.py\n'
            f'Root-Is-Purelib: false\nTag: {tag}\n')


def assemble(pure_wheel: Path, stage: Path, *, distro: str, python: str, out_dir: Path) -> Path:
    """Write the binary wheel into ``out_dir`` and return its path.

    :param pure_wheel: the ``py3-none-any`` wheel that setup.py builds.
    :param stage: install prefix of the message package built for ``distro`` and ``python``.
    :param python: ``X.Y`` of the target interpreter.
    """
    version = wheel_version(distro)
    tag = f'cp{python.replace(".", "")}-cp{python.replace(".", "")}-{PLATFORM_TAG}'
    members: Dict[str, Tuple[bytes, int]] = {}
    with zipfile.ZipFile(pure_wheel) as pure:
        old = pure_wheel.name.split('-')[1]
        for info in pure.infolist():
            if info.is_dir():
                continue
            top, sep, rest = info.filename.partition('/')
            if top == f'{NAME}-{old}.dist-info':
                if rest in ('RECORD', 'WHEEL'):
                    continue
                top = f'{NAME}-{version}.dist-info'
            elif top == f'{NAME}-{old}.data':
                top = f'{NAME}-{version}.data'
            data = pure.read(info)
            if rest == 'METADATA' and top.endswith('.dist-info'):
                data = _metadata(data.decode(), version, distro).encode()
            members[top + sep + rest] = (data, 0o644)
    for arcname, path in message_files(stage, python):
        arcname = arcname.format(version=version)
        members[arcname] = (path.read_bytes(), 0o755 if path.suffix == '.so' else 0o644)
    members[PTH_NAME] = (PTH_LINE.encode(), 0o644)
    dist_info = f'{NAME}-{version}.dist-info'
    members[f'{dist_info}/WHEEL'] = (_wheel_file(tag).encode(), 0o644)

    out_dir.mkdir(parents=True, exist_ok=True)
    target = out_dir / f'{NAME}-{version}-{tag}.whl'
    partial = target.with_name(target.name + '.part')
    record = io.StringIO()
    writer = csv.writer(record, lineterminator='\n')
    # dist-info last, RECORD at the very end (the wheel specification's recommended order).
    order: List[str] = sorted(members, key=lambda n: (n.startswith(dist_info), n))
    with zipfile.ZipFile(partial, 'w', zipfile.ZIP_DEFLATED) as whl:
        for name in order:
            data, mode = members[name]
            info = zipfile.ZipInfo(name, ZIP_TIME)
            info.external_attr = (0o100000 | mode) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            whl.writestr(info, data)
            writer.writerow([name, _record_hash(data), len(data)])
        writer.writerow([f'{dist_info}/RECORD', '', ''])
        info = zipfile.ZipInfo(f'{dist_info}/RECORD', ZIP_TIME)
        info.external_attr = (0o100000 | 0o644) << 16
        info.compress_type = zipfile.ZIP_DEFLATED
        whl.writestr(info, record.getvalue())
    partial.replace(target)
    return target
