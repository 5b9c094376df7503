"""Build binary wheels of conveyor_twin that carry the interface packages (no ROS install needed).

    python tools/build_wheel.py [--distro jazzy|kilted|all] [--python 3.11|3.12|PATH|all]
                                [--out dist]

For each distro and Python this writes
``dist/conveyor_twin-<version>+<distro>-cpXY-cpXY-manylinux_2_28_x86_64.whl``: the
``conveyor_twin`` package (console scripts, pytest plugin, cells), ``conveyor_twin_msgs`` and
``simulation_interfaces`` (Python modules, typesupport libraries, ament index entries),
declaring the ROS 2 wheels of ``requirements/<distro>.txt`` as dependencies. Steps, each reused
while its inputs are unchanged:

1. a build environment with the distro's ROS wheels for that Python: ``.venv-<distro>`` when
   ``make setup`` made it for the same Python, else ``build/wheel/<distro>-cpXY/env``;
2. ``msg_defs/`` and ``interfaces/simulation_interfaces/`` built with cmake + make into
   ``build/wheel/<distro>-cpXY/stage``, their libraries kept within the manylinux_2_28 policy
   (``tools/wheelbuild/glibcxx_compat.cpp``) and compiled with the source paths mapped away;
   ``make setup``'s own builds (``build/msg_defs-<distro>``,
   ``build/simulation_interfaces-<distro>``, built the same way) are installed from instead when
   they are current;
3. the pure ``conveyor_twin`` wheel from setup.py (``pip wheel``, PEP 517, from a copy of the
   sources), then the binary wheel assembled from both (``tools/wheelbuild/assemble.py``);
4. checked: no path of this machine in any file, every library within manylinux_2_28
   (``tools/wheelbuild/check.py``).

Needs what ``make setup`` needs (Python 3.11/3.12 with headers, cmake, make, C/C++ compilers,
the package index). Combinations whose interpreter is not installed are skipped with a message
(``--python all``) or refused (an explicit ``--python``).
"""

import argparse
import fcntl
import hashlib
import os
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

sys.path.insert(0, str(Path(__file__).resolve().parent))

from wheelbuild.assemble import assemble  # noqa: E402
from wheelbuild.check import check_elf, find_paths  # noqa: E402
from wheelbuild.metadata import DISTROS, ROOT, check_distro, read_pins  # noqa: E402

PYTHONS = ('3.11', '3.12')
COMPAT = ROOT / 'tools' / 'wheelbuild' / 'glibcxx_compat.cpp'
#: The interface packages the wheel carries: (source directory, name of its build and stamp).
INTERFACE_SOURCES = (('msg_defs', 'msg_defs'),
                     ('interfaces/simulation_interfaces', 'simulation_interfaces'))
#: What goes into the pure wheel's source copy (setup.py's inputs).
SOURCES = ('setup.py', 'setup.cfg', 'package.xml', 'resource', 'conveyor_twin', 'msg_defs')
IGNORED = shutil.ignore_patterns('__pycache__', '*.pyc', '*.nbi', '*.nbc', '*.egg-info')
#: Variables a venv's python sets for its children; no build step may inherit them.
INHERITED = ('LD_LIBRARY_PATH', '_ROS_WHEELS_BOOTSTRAP_COMPLETE', 'AMENT_PREFIX_PATH',
             'CMAKE_PREFIX_PATH', 'PYTHONPATH', 'PYTHONHOME', 'VIRTUAL_ENV')


class BuildError(RuntimeError):
    """A step of the wheel build failed; the message says which and where its log is."""


def say(text: str) -> None:
    """Print a progress line."""
    print(f'build_wheel: {text}', flush=True)


def clean_environ(**extra: str) -> Dict[str, str]:
    """Return this process's environment without what another environment's python set.

    ros-wheels-bootstrapper re-executes a venv's python with ``LD_LIBRARY_PATH`` pointing into
    that venv, and marks it done for every child; a child running another environment's python
    must start without both (and without an inherited ``AMENT_PREFIX_PATH``).
    """
    env = {k: v for k, v in os.environ.items() if k not in INHERITED}
    env.update(PIP_NO_INPUT='1', PIP_DISABLE_PIP_VERSION_CHECK='1', **extra)
    return env


def run(cmd: Sequence[str], log: Path, what: str, env: Optional[Dict[str, str]] = None,
        cwd: Optional[Path] = None) -> None:
    """Run ``cmd`` with its output appended to ``log``; raise BuildError naming ``what``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, 'a') as out:
        out.write(f'\n$ {" ".join(map(str, cmd))}\n')
        out.flush()
        code = subprocess.run(list(map(str, cmd)), stdout=out, stderr=subprocess.STDOUT,
                              stdin=subprocess.DEVNULL, env=env or clean_environ(),
                              cwd=cwd).returncode
    if code:
        tail = ''.join(log.read_text().splitlines(keepends=True)[-30:])
        raise BuildError(f'{what} failed (exit code {code}); last lines of {log}:\n{tail}')


def runs(python: str) -> bool:
    """Return whether ``python`` starts."""
    try:
        return subprocess.run([python, '-c', ''], stdin=subprocess.DEVNULL,
                              capture_output=True).returncode == 0
    except OSError:
        return False


def find_python(spec: str) -> Optional[Path]:
    """Return the interpreter for ``3.11``, ``3.12`` or a path; None if it is not installed.

    A bare version is ``python3.X`` on PATH if it runs, else the newest pyenv installation.
    """
    if '/' in spec:
        return Path(spec) if runs(spec) else None
    spec = spec[len('python'):] if spec.startswith('python') else spec
    name = f'python{spec}'
    if shutil.which(name) and runs(name):
        return Path(subprocess.run([name, '-c', 'import sys; print(sys.executable)'],
                                   capture_output=True, text=True).stdout.strip())
    pyenv_root = Path(os.environ.get('PYENV_ROOT', Path.home() / '.pyenv'))
    for candidate in sorted(pyenv_root.glob(f'versions/{spec}.*/bin/{name}'), reverse=True):
        if runs(str(candidate)):
            return candidate
    return None


def python_version(python: Path) -> str:
    """Return ``X.Y`` of an interpreter, checking its headers (msg_defs compiles an extension)."""
    out = subprocess.run([str(python), '-c', 'import sys, sysconfig, os; '
                          'print("%d.%d" % sys.version_info[:2]); '
                          'print(os.path.isfile(os.path.join(sysconfig.get_paths()["include"], '
                          '"Python.h")))'], capture_output=True, text=True, check=True).stdout
    version, headers = out.split()
    if version not in PYTHONS:
        raise BuildError(f'{python} is Python {version}; the ROS 2 wheels exist for '
                         f'{" and ".join(PYTHONS)}')
    if headers != 'True':
        raise BuildError(f'{python} has no Python.h: install the Python {version} development '
                         f'headers (Debian/Ubuntu: python{version}-dev)')
    return version


def digest(paths: Iterable[Path], *extra: str) -> str:
    """Return a SHA-256 over files (names and bytes, directories recursively) and strings."""
    h = hashlib.sha256()
    for path in paths:
        files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
        for f in files:
            h.update(str(f.relative_to(ROOT)).encode() + b'\0' + f.read_bytes())
    for text in extra:
        h.update(text.encode() + b'\0')
    return h.hexdigest()


def stamp_ok(path: Path, value: str) -> bool:
    """Return whether the stamp file ``path`` holds ``value``."""
    return path.is_file() and path.read_text() == value


def build_env(distro: str, python: Path, version: str, work: Path) -> Path:
    """Return an environment prefix with the distro's ROS wheels (and the build chain)."""
    dev = ROOT / f'.venv-{distro}'
    env_file = dev / '.setup' / 'env'
    # make setup writes its requirements stamp after installing and patching the wheels.
    if (stamp_ok(env_file, f'distro={distro} python={version}\n')
            and stamp_ok(dev / '.setup' / 'requirements', setup_req_hash(distro) + '\n')
            and runs(str(dev / 'bin' / 'python'))):
        say(f'build environment: .venv-{distro} (made by make setup for Python {version})')
        return dev
    env = work / 'env'
    requirements = ROOT / 'requirements' / f'{distro}.txt'
    lines = [line.strip() for line in requirements.read_text().splitlines()
             if line.strip() and not line.startswith(('#', '-r'))]
    numpy = f'numpy=={read_pins(requirements)["numpy"]}'
    stamp = env / '.wheel-env'
    value = digest([requirements, ROOT / 'requirements' / 'common.txt'], str(python))
    if stamp_ok(stamp, value) and runs(str(env / 'bin' / 'python')):
        say(f'build environment: {env.relative_to(ROOT)} up to date')
        return env
    say(f'creating the build environment {env.relative_to(ROOT)} (ROS 2 {distro}, Python '
        f'{version}; minutes on a cold pip cache)')
    shutil.rmtree(env, ignore_errors=True)
    log = work / 'env.log'
    log.unlink(missing_ok=True)
    run([python, '-m', 'venv', env], log, f'{python} -m venv')
    run([env / 'bin' / 'python', '-m', 'pip', 'install', '-q', '--progress-bar', 'off',
         numpy, *lines], log, f'installing the ROS 2 {distro} wheels into {env}')
    run([env / 'bin' / 'python', ROOT / 'tools' / 'patch_wheel_cmake.py'], log,
        'patching the wheels\' CMake files')
    stamp.write_text(value)
    return env


def _sha256sum(paths: Iterable[str]) -> str:
    """Return the SHA-256 of what ``sha256sum PATHS`` prints in the repository."""
    lines = ''.join(f'{hashlib.sha256((ROOT / p).read_bytes()).hexdigest()}  {p}\n'
                    for p in paths)
    return hashlib.sha256(lines.encode()).hexdigest()


def setup_req_hash(distro: str) -> str:
    """Return the hash tools/setup_env.sh stamps its installed requirements with, for the
    requirements files as they are now."""
    return _sha256sum(['requirements/common.txt', f'requirements/{distro}.txt'])


def setup_msg_hash(distro: str, source: str = 'msg_defs') -> str:
    """Return the hash tools/setup_env.sh stamps its build of an interface package with (by
    default msg_defs/), for the sources and requirements as they are now."""
    tree = sorted((str(p.relative_to(ROOT)) for p in (ROOT / source).rglob('*')
                   if p.is_file()), key=lambda name: name.encode())
    value = f'{_sha256sum(tree)} {setup_req_hash(distro)} {ROOT}/.venv-{distro}'
    return hashlib.sha256(value.encode()).hexdigest()


def setup_stage(distro: str, version: str, work: Path) -> Optional[Path]:
    """Install ``make setup``'s builds of the interface packages into ``work/setup-stage`` and
    return it, if those builds are current, for this Python and built as for a wheel; else
    return None."""
    dev = ROOT / f'.venv-{distro}'
    if not stamp_ok(dev / '.setup' / 'env', f'distro={distro} python={version}\n'):
        return None
    for source, name in INTERFACE_SOURCES:
        cache = ROOT / 'build' / f'{name}-{distro}' / 'CMakeCache.txt'
        if not (stamp_ok(dev / '.setup' / name, setup_msg_hash(distro, source) + '\n')
                and cache.is_file() and 'libglibcxx_compat.a' in cache.read_text()):
            return None
    stage = work / 'setup-stage'
    shutil.rmtree(stage, ignore_errors=True)
    log = work / 'setup-stage.log'
    log.unlink(missing_ok=True)
    for source, name in INTERFACE_SOURCES:
        run(['cmake', '--install', ROOT / 'build' / f'{name}-{distro}', '--prefix', stage], log,
            f'installing build/{name}-{distro} into {stage}')
        say(f'{source}/: reusing make setup\'s current build/{name}-{distro}')
    return stage


def _cmake_command(source: str, build: Path, stage: Path, env: Path) -> List[object]:
    """Return the cmake configure command of one interface package, built as for a wheel."""
    compat = build / 'libglibcxx_compat.a'
    cc = os.environ.get('CC', 'cc')
    cxx = os.environ.get('CXX', 'c++')
    # Source and build paths must not end up in the libraries (__FILE__ in error messages).
    mapping = f'-ffile-prefix-map={build}=. -ffile-prefix-map={ROOT}=.'
    return ['cmake', '-S', ROOT / source, '-B', build, f'-DCMAKE_INSTALL_PREFIX={stage}',
            '-DCMAKE_BUILD_TYPE=Release', '-DBUILD_TESTING=OFF', f'-DCMAKE_C_COMPILER={cc}',
            f'-DCMAKE_CXX_COMPILER={cxx}', f'-DPython3_EXECUTABLE={env / "bin" / "python"}',
            '-DPython3_FIND_VIRTUALENV=ONLY', f'-DCMAKE_C_FLAGS={mapping}',
            f'-DCMAKE_CXX_FLAGS={mapping}', f'-DCMAKE_CXX_STANDARD_LIBRARIES={compat}',
            '-DCMAKE_SHARED_LINKER_FLAGS=-Wl,--exclude-libs,libglibcxx_compat.a']


def build_messages(distro: str, env: Path, version: str, work: Path, jobs: int) -> Path:
    """Build the interface packages (:data:`INTERFACE_SOURCES`) against ``env`` and install them
    into ``work/stage``; return the stage."""
    stage = work / 'stage'
    commands = {name: _cmake_command(source, work / name, stage, env)
                for source, name in INTERFACE_SOURCES}
    stamp = work / 'stage.stamp'
    value = digest([*(ROOT / source for source, _ in INTERFACE_SOURCES), COMPAT,
                    ROOT / 'requirements' / f'{distro}.txt'], str(env), version,
                   *(' '.join(map(str, c)) for c in commands.values()))
    sites = [stage / 'lib' / f'python{version}' / 'site-packages' / package
             for package in ('conveyor_twin_msgs', 'simulation_interfaces')]
    if stamp_ok(stamp, value) and all(site.is_dir() for site in sites):
        say(f'interface packages for {distro}, Python {version}: up to date')
        return stage
    shutil.rmtree(stage, ignore_errors=True)
    cxx = os.environ.get('CXX', 'c++')
    environ = clean_environ(AMENT_PREFIX_PATH=str(env), CMAKE_PREFIX_PATH=str(env),
                            PATH=f'{env / "bin"}{os.pathsep}{os.environ["PATH"]}')
    for source, name in INTERFACE_SOURCES:
        say(f'building {source}/ against ROS 2 {distro}, Python {version}')
        build = work / name
        shutil.rmtree(build, ignore_errors=True)
        build.mkdir(parents=True)
        log = build / 'build.log'
        run([cxx, '-fPIC', '-O2', '-c', COMPAT, '-o', build / 'glibcxx_compat.o'], log,
            'compiling glibcxx_compat.cpp')
        run(['ar', 'rcs', build / 'libglibcxx_compat.a', build / 'glibcxx_compat.o'], log,
            'archiving glibcxx_compat.o')
        run(commands[name], log, f'configuring {source}/', env=environ)
        run(['make', '-C', build, f'-j{jobs}', 'install'], log, f'building {source}/',
            env=environ)
    missing = [str(site) for site in sites if not site.is_dir()]
    if missing:
        raise BuildError(f'the interface packages installed, but not into {missing}')
    stamp.write_text(value)
    return stage


def pure_wheel(env: Path, tmp: Path) -> Path:
    """Build the ``py3-none-any`` wheel of setup.py from a copy of its inputs; return it."""
    src = tmp / 'src'
    src.mkdir()
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=IGNORED)
        else:
            shutil.copy2(path, src / name)
    log = tmp / 'pure.log'
    run([env / 'bin' / 'python', '-m', 'pip', 'wheel', '-q', '--no-deps', '-w', tmp / 'pure', src],
        log, 'building the conveyor_twin wheel from setup.py')
    wheels = list((tmp / 'pure').glob('conveyor_twin-*-py3-none-any.whl'))
    if len(wheels) != 1:
        raise BuildError(f'pip wheel wrote {wheels}; expected one '
                         'conveyor_twin-*-py3-none-any.whl')
    return wheels[0]


def build_one(distro: str, python: Path, out: Path, jobs: int) -> Path:
    """Build, check and return the wheel of one distro and interpreter."""
    start = time.monotonic()
    version = python_version(python)
    work = ROOT / 'build' / 'wheel' / f'{distro}-cp{version.replace(".", "")}'
    work.mkdir(parents=True, exist_ok=True)
    # One build of a distro and Python at a time (make wheel and a test at once wait in turn).
    with open(work / '.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return _build_locked(distro, python, version, work, out, jobs, start)


def _build_locked(distro: str, python: Path, version: str, work: Path, out: Path, jobs: int,
                  start: float) -> Path:
    """Build and check one wheel while holding the lock of its work directory."""
    env = build_env(distro, python, version, work)
    stage = (setup_stage(distro, version, work)
             or build_messages(distro, env, version, work, jobs))
    with tempfile.TemporaryDirectory(prefix='conveyor_twin_wheel_') as tmp:
        wheel = assemble(pure_wheel(env, Path(tmp)), stage, distro=distro, python=version,
                         out_dir=out)
        forbidden = [str(ROOT), str(ROOT.resolve()), str(work), str(env), str(env.resolve()),
                     tmp, str(Path(tmp).resolve()), str(python.parent.parent)]
        findings = find_paths(wheel, forbidden) + check_elf(wheel, env)
    if findings:
        wheel.unlink()
        raise BuildError(f'{wheel.name} failed its checks (removed):\n  ' + '\n  '.join(findings))
    size = wheel.stat().st_size / 1e6
    say(f'{wheel} ({size:.1f} MB) in {time.monotonic() - start:.0f} s: no build paths, '
        'manylinux_2_28 policy met')
    return wheel


def targets(distros: List[str], pythons: List[str]) -> List[Tuple[str, Path]]:
    """Return the (distro, interpreter) pairs to build; say which ones this machine lacks."""
    explicit = pythons != ['all']
    found = []
    for spec in (pythons if explicit else list(PYTHONS)):
        path = find_python(spec)
        if path is None:
            if explicit:
                raise BuildError(f'Python {spec} is not installed (or does not run)')
            say(f'skipping Python {spec}: no interpreter found (python{spec} or pyenv)')
            continue
        found.append(path)
    return [(d, p) for d in distros for p in found]


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Build the requested wheels; return 0 when all were built and checked."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--distro', action='append',
                        help=f'ROS 2 distro: {", ".join(DISTROS)} or all (repeatable; '
                             'default: $ROS_DISTRO or jazzy)')
    parser.add_argument('--python', action='append',
                        help='3.11, 3.12, an interpreter path, or all (repeatable; default: '
                             '$PYTHON, else 3.11, else 3.12)')
    parser.add_argument('--out', type=Path, default=ROOT / 'dist', help='output directory')
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 2, help='make jobs')
    args = parser.parse_args(argv)
    distros = args.distro or [os.environ.get('ROS_DISTRO', 'jazzy')]
    distros = list(DISTROS) if 'all' in distros else distros
    pythons = args.python or ([os.environ['PYTHON']] if os.environ.get('PYTHON') else None)
    if pythons is None:
        pythons = ['3.11'] if find_python('3.11') else ['3.12']
    pythons = ['all'] if 'all' in pythons else pythons
    try:
        for distro in distros:
            check_distro(distro)
        built = [build_one(distro, python, args.out.resolve(), args.jobs)
                 for distro, python in targets(distros, pythons)]
    except (BuildError, ValueError, FileNotFoundError) as exc:
        print(f'build_wheel: error: {exc}', file=sys.stderr)
        return 1
    if not built:
        print('build_wheel: error: nothing built (no interpreter found)', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
