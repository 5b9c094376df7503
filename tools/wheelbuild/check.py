"""Check a binary wheel of conveyor_twin before it is handed out.

- **No path of the build machine**: every member's name and bytes are searched for the
  directories the build used (repository, build tree, build environment).
- **manylinux_2_28**: every ELF file needs no symbol version newer than the policy allows
  (GLIBC 2.28, GLIBCXX 3.4.25, CXXABI 1.3.11), has no RPATH/RUNPATH outside ``$ORIGIN``, and
  links only against the policy's system libraries, libraries in the wheel and libraries of the
  ROS wheels (found in ``ros_lib_dirs``, the build environment's ``lib/`` and ``ros_*.libs``).

``python tools/wheelbuild/check.py WHEEL [--forbid PATH ...] [--ros-prefix VENV]`` runs both and
exits 1 on a finding.
"""

import argparse
from pathlib import Path
import re
import subprocess
import sys
import tempfile
from typing import Dict, Iterable, List, Optional, Sequence, Set, Tuple
import zipfile

#: Newest symbol versions manylinux_2_28 (RHEL 8: glibc 2.28, GCC 8's libstdc++) provides.
POLICY_2_28: Dict[str, Tuple[int, ...]] = {
    'GLIBC': (2, 28), 'GLIBCXX': (3, 4, 25), 'CXXABI': (1, 3, 11)}
#: System libraries a manylinux wheel may link against without shipping them.
SYSTEM_LIBS = frozenset({
    'libc.so.6', 'libm.so.6', 'libdl.so.2', 'librt.so.1', 'libpthread.so.0', 'libutil.so.1',
    'libstdc++.so.6', 'libgcc_s.so.1', 'ld-linux-x86-64.so.2', 'libresolv.so.2'})
ELF_MAGIC = b'\x7fELF'


def find_paths(wheel: Path, needles: Iterable[str]) -> List[str]:
    """Return ``member: path`` for every forbidden path in a member's name or bytes."""
    needles = sorted({n.rstrip('/') for n in needles if n and n.rstrip('/')}, key=len)
    findings = []
    with zipfile.ZipFile(wheel) as whl:
        for info in whl.infolist():
            data = whl.read(info)
            for needle in needles:
                if needle in info.filename or needle.encode() in data:
                    findings.append(f'{info.filename}: contains {needle}')
    return findings


def _objdump(path: Path) -> str:
    return subprocess.run(['objdump', '-p', str(path)], check=True, capture_output=True,
                          text=True).stdout


def elf_findings(name: str, dump: str, provided: Optional[Set[str]],
                 policy: Dict[str, Tuple[int, ...]] = POLICY_2_28) -> List[str]:
    """Return what in one ELF file's ``objdump -p`` output breaks the policy.

    :param provided: library names the wheel and the ROS wheels provide; None skips the check
        of the libraries linked against.
    """
    findings = []
    for family, version in re.findall(r'\b(GLIBC|GLIBCXX|CXXABI)_([0-9][0-9.]*)\b', dump):
        numbers = tuple(int(p) for p in version.split('.'))
        if numbers > policy[family]:
            findings.append(f'{name}: needs {family}_{version}, manylinux_2_28 allows up to '
                            f'{family}_{".".join(map(str, policy[family]))}')
    for kind, value in re.findall(r'^\s*(RPATH|RUNPATH)\s+(\S+)', dump, re.M):
        if any(not part.startswith('$ORIGIN') for part in value.split(':')):
            findings.append(f'{name}: {kind} {value} (only $ORIGIN-relative paths are allowed)')
    for needed in re.findall(r'^\s*NEEDED\s+(\S+)', dump, re.M):
        if provided is not None and needed not in SYSTEM_LIBS and needed not in provided:
            findings.append(f'{name}: links against {needed}, which neither the system policy, '
                            'the wheel nor the ROS wheels provide')
    return sorted(set(findings))


def ros_libraries(prefix: Path) -> Set[str]:
    """Return the library file names the ROS wheels installed into ``prefix`` provide."""
    names = {p.name for p in (prefix / 'lib').glob('*.so*')}
    for libs in prefix.glob('lib/python3.*/site-packages/ros_*.libs'):
        names |= {p.name for p in libs.iterdir()}
    return names


def check_elf(wheel: Path, ros_prefix: Optional[Path]) -> List[str]:
    """Return the manylinux_2_28 findings of every ELF file in ``wheel``.

    :param ros_prefix: environment with the ROS wheels, to resolve the libraries linked
        against; None checks symbol versions and RPATHs only.
    """
    findings: List[str] = []
    with zipfile.ZipFile(wheel) as whl, tempfile.TemporaryDirectory() as tmp:
        elves = [i for i in whl.infolist() if whl.read(i)[:4] == ELF_MAGIC]
        provided = (None if ros_prefix is None else
                    {Path(i.filename).name for i in elves} | ros_libraries(ros_prefix))
        for info in elves:
            path = Path(tmp) / Path(info.filename).name
            path.write_bytes(whl.read(info))
            findings += elf_findings(info.filename, _objdump(path), provided)
    return findings


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Check wheels; print the findings and return 1 if there are any."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('wheels', nargs='+', type=Path)
    parser.add_argument('--forbid', action='append', default=[],
                        help='a path that must not occur in the wheel (repeatable)')
    parser.add_argument('--ros-prefix', type=Path,
                        help='environment with the ROS wheels the wheel depends on (without '
                             'it, the libraries linked against are not checked)')
    args = parser.parse_args(argv)
    failed = False
    for wheel in args.wheels:
        findings = find_paths(wheel, args.forbid) + check_elf(wheel, args.ros_prefix)
        for finding in findings:
            print(f'{wheel.name}: {finding}', file=sys.stderr)
        failed |= bool(findings)
        if not findings:
            scope = '' if args.ros_prefix else ' (libraries linked against not checked)'
            print(f'{wheel.name}: no build paths, manylinux_2_28 policy met{scope}')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
