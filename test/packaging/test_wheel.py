"""The binary wheel: built, checked, installed into a clean environment outside the repository
and used there as a user's project uses it.

The slow test builds the wheel of this environment's distro and Python (``tools/build_wheel.py``;
the message build in ``build/wheel/`` is reused while its inputs are unchanged), creates a
virtual environment in a temporary directory with nothing but the wheel, its declared
dependencies from the package index and the user's own test dependencies (pytest,
pytest-xdist), and there runs ``conveyor-twin --version``, ``conveyor-twin run --mode fast
--duration 1`` and the tests of ``examples/user_project`` with the plugin (``pytest -p
conveyor_twin -n 2``). Nothing of this repository or its environment is on the paths of those
processes, and nothing is sourced.
"""

import importlib.metadata
import json
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Sequence
import zipfile

import pytest

from conveyor_twin import __version__
from conveyor_twin.testing.ros_env import ros_subprocess_env
from conveyor_twin.wire.schemas import SCHEMAS

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / 'tools'))

from build_wheel import INHERITED  # noqa: E402
from wheelbuild.check import check_elf, elf_findings, find_paths  # noqa: E402
from wheelbuild.metadata import DISTROS, PLATFORM_TAG, read_pins, requires_dist  # noqa: E402

USER_PROJECT = ROOT / 'examples' / 'user_project'
BUILD_TIMEOUT = 1800.0  # [s] a cold build: the build environment and msg_defs/
INSTALL_TIMEOUT = 900.0  # [s] pip on a cold cache
RUN_TIMEOUT = 900.0  # [s] the first run in a new environment compiles the numba kernels
#: The user's own test dependencies, at the versions this repository tests with.
USER_TEST_DEPENDENCIES = ('pytest', 'pytest-xdist')
#: Inspects the new environment from inside (printed as JSON).
PROBE = '''
import importlib.metadata, json, os, sys
import conveyor_twin, conveyor_twin_msgs.msg, simulation_interfaces.srv
from conveyor_twin.wire import msg_files, schemas
from ament_index_python.packages import get_package_share_directory
from rclpy.serialization import deserialize_message, serialize_message
message = conveyor_twin_msgs.msg.BeltCommand(belt='main', speed=0.25)
print(json.dumps({
    'conveyor_twin': conveyor_twin.__file__,
    'conveyor_twin_msgs': conveyor_twin_msgs.msg.__file__,
    'share': [get_package_share_directory(p) for p in ('conveyor_twin', 'conveyor_twin_msgs')],
    'round_trip': deserialize_message(serialize_message(message), type(message)) == message,
    'metadata_version': importlib.metadata.version('conveyor_twin'),
    'prefix': sys.prefix,
    'msg_defs': str(msg_files.contract_dir()),
    'simulation_interfaces': [
        simulation_interfaces.srv.__file__, get_package_share_directory('simulation_interfaces'),
        deserialize_message(serialize_message(simulation_interfaces.srv.StepSimulation.Request(
            steps=3)), simulation_interfaces.srv.StepSimulation.Request).steps],
    'schemas': schemas.SCHEMAS,
}))
'''


def current_distro() -> str:
    """Return the ROS 2 distro of this environment (the one whose rclpy pin is installed)."""
    rclpy = importlib.metadata.version('ros-rclpy')
    for distro in DISTROS:
        if read_pins(ROOT / 'requirements' / f'{distro}.txt')['ros-rclpy'] == rclpy:
            return distro
    pytest.fail(f'ros-rclpy {rclpy} is pinned by none of requirements/<distro>.txt')


def user_environment(venv: Path) -> Dict[str, str]:
    """Return the environment of a process in the user's venv: this test's ROS domain on
    loopback, nothing of this repository's environment, the venv's bin/ first on PATH."""
    env = ros_subprocess_env()
    for name in INHERITED + ('PYTEST_ADDOPTS', 'PYTEST_XDIST_WORKER',
                             'PYTEST_XDIST_WORKER_COUNT', 'PYTEST_CURRENT_TEST'):
        env.pop(name, None)
    paths = [p for p in env.get('PATH', '').split(os.pathsep)
             if p and not Path(p).resolve().is_relative_to(ROOT)]
    env['PATH'] = os.pathsep.join([str(venv / 'bin')] + paths)
    env.update(PIP_NO_INPUT='1', PIP_DISABLE_PIP_VERSION_CHECK='1')
    return env


def run(cmd: Sequence[object], *, env: Dict[str, str], cwd: Path,
        timeout: float) -> subprocess.CompletedProcess:
    """Run ``cmd`` to its end in a process group of its own (killed whole on timeout)."""
    process = subprocess.Popen([str(c) for c in cmd], cwd=cwd, env=env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        output, _ = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        output, _ = process.communicate()
        pytest.fail(f'{" ".join(map(str, cmd))} did not finish within {timeout:.0f} s:\n'
                    f'{output[-4000:]}')
    return subprocess.CompletedProcess(cmd, process.returncode, output, '')


def check(result: subprocess.CompletedProcess, what: str) -> str:
    """Return the output of a finished command; fail with its output unless it exited 0."""
    assert result.returncode == 0, \
        f'{what}: exit code {result.returncode}\n{result.stdout[-6000:]}'
    return result.stdout


@pytest.mark.slow
@pytest.mark.ros
def test_the_wheel_installs_and_runs_in_a_clean_environment():
    distro = current_distro()
    python = Path(getattr(sys, '_base_executable', sys.executable))
    tag = f'cp{sys.version_info[0]}{sys.version_info[1]}'
    pins = read_pins(ROOT / 'requirements' / f'{distro}.txt')
    times: List[str] = []
    start = time.monotonic()

    def lap(what: str) -> None:
        times.append(f'{what} {time.monotonic() - start:.0f} s')

    with tempfile.TemporaryDirectory(prefix='conveyor_twin_wheel_test_') as tmp_name:
        tmp = Path(tmp_name).resolve()
        assert not tmp.is_relative_to(ROOT)
        venv = tmp / 'venv'
        env = user_environment(venv)

        check(run([sys.executable, ROOT / 'tools' / 'build_wheel.py', '--distro', distro,
                   '--python', python, '--out', tmp / 'dist'],
                  env=env, cwd=tmp, timeout=BUILD_TIMEOUT), 'tools/build_wheel.py')
        lap('built')
        wheels = list((tmp / 'dist').glob('*.whl'))
        assert [w.name for w in wheels] == [
            f'conveyor_twin-{__version__}+{distro}-{tag}-{tag}-{PLATFORM_TAG}.whl']
        wheel = wheels[0]

        check(run([python, '-m', 'venv', venv], env=env, cwd=tmp, timeout=INSTALL_TIMEOUT),
              'python -m venv')
        user_tests = [f'{name}=={pins[name]}' for name in USER_TEST_DEPENDENCIES]
        check(run([venv / 'bin' / 'python', '-m', 'pip', 'install', '-q', '--progress-bar',
                   'off', wheel, *user_tests], env=env, cwd=tmp, timeout=INSTALL_TIMEOUT),
              'pip install of the wheel')
        check(run([venv / 'bin' / 'python', '-m', 'pip', 'check'], env=env, cwd=tmp,
                  timeout=INSTALL_TIMEOUT), 'pip check')
        lap('installed')

        # The wheel: no path of this machine, libraries within its platform tag's policy
        # (resolved against the ROS wheels as pip installed them).
        forbidden = [str(ROOT), str(ROOT.resolve()), sys.prefix, str(Path(sys.prefix).resolve())]
        assert find_paths(wheel, forbidden) == []
        assert check_elf(wheel, venv) == []

        probe = json.loads(check(run([venv / 'bin' / 'python', '-c', PROBE], env=env, cwd=tmp,
                                     timeout=RUN_TIMEOUT), 'import in the new environment'))
        site = venv / 'lib' / f'python{sys.version_info[0]}.{sys.version_info[1]}'
        for name in ('conveyor_twin', 'conveyor_twin_msgs'):
            assert Path(probe[name]).is_relative_to(site), (name, probe[name])
        assert [Path(p) for p in probe['share']] == [
            venv / 'share' / 'conveyor_twin', venv / 'share' / 'conveyor_twin_msgs']
        assert probe['round_trip'] is True
        assert probe['metadata_version'] == f'{__version__}+{distro}'
        # the recorded schemas come from the wheel's copy of msg_defs/, byte for byte
        assert Path(probe['msg_defs']).is_relative_to(site)
        assert Path(probe['msg_defs']).parts[-4:] == ('conveyor_twin', 'wire', 'msg',
                                                      'conveyor_twin_msgs')
        assert probe['schemas'] == SCHEMAS
        # simulation_interfaces, built into the wheel (it has no PyPI wheel of its own)
        module, share, steps = probe['simulation_interfaces']
        assert Path(module).is_relative_to(site), module
        assert (Path(share), steps) == (venv / 'share' / 'simulation_interfaces', 3)

        out = check(run([venv / 'bin' / 'conveyor-twin', '--version'], env=env, cwd=tmp,
                        timeout=RUN_TIMEOUT), 'conveyor-twin --version')
        assert out.strip() == f'conveyor-twin {__version__}'
        # The first run also compiles the numba kernels into the new environment's cache, so the
        # test workers below load them.
        out = check(run([venv / 'bin' / 'conveyor-twin', 'run', '--mode', 'fast', '--duration',
                         '1'], env=env, cwd=tmp, timeout=RUN_TIMEOUT), 'conveyor-twin run')
        assert '1000 steps (1.000 s simulated)' in out, out[-3000:]
        lap('ran')

        project = tmp / 'user_project'
        shutil.copytree(USER_PROJECT, project)
        out = check(run([venv / 'bin' / 'python', '-m', 'pytest', '-p', 'conveyor_twin',
                         '-p', 'no:cacheprovider', '-n', '2', '-q'], env=env, cwd=project,
                        timeout=RUN_TIMEOUT), "the user's tests")
        assert '3 passed' in out, out[-3000:]
        lap('user tests passed')
        print(f'{wheel.name}: {wheel.stat().st_size / 1e6:.2f} MB; ' + ', '.join(times))


# --- the checks themselves --------------------------------------------------------------------

OBJDUMP = '''
Dynamic Section:
  NEEDED               libstdc++.so.6
  NEEDED               librosidl_runtime_c.so
  NEEDED               libelsewhere.so
  RUNPATH              /home/builder/lib:$ORIGIN
Version References:
  required from libstdc++.so.6:
    0x0297f871 0x00 04 GLIBCXX_3.4.21
    0x08922974 0x00 05 GLIBCXX_3.4.29
  required from libc.so.6:
    0x06969194 0x00 03 GLIBC_2.14
'''


def test_the_policy_check_names_what_a_library_breaks():
    findings = elf_findings('lib/libx.so', OBJDUMP, provided={'librosidl_runtime_c.so'})
    assert findings == sorted([
        'lib/libx.so: needs GLIBCXX_3.4.29, manylinux_2_28 allows up to GLIBCXX_3.4.25',
        'lib/libx.so: RUNPATH /home/builder/lib:$ORIGIN (only $ORIGIN-relative paths are '
        'allowed)',
        'lib/libx.so: links against libelsewhere.so, which neither the system policy, the wheel '
        'nor the ROS wheels provide'])
    assert elf_findings('lib/liby.so', OBJDUMP.replace('GLIBCXX_3.4.29', 'GLIBCXX_3.4.25')
                        .replace('/home/builder/lib:', '').replace('libelsewhere', 'libm'),
                        provided={'librosidl_runtime_c.so', 'libm.so'}) == []


def test_the_path_scan_finds_a_path_in_names_and_contents(tmp_path):
    wheel = tmp_path / 'x.whl'
    with zipfile.ZipFile(wheel, 'w') as whl:
        whl.writestr('a/b.txt', b'prefix=/build/here/venv\n')
        whl.writestr('c.so', b'\x7fELF\0/build/there\0')
        whl.writestr('clean.py', b'x = 1\n')
    assert find_paths(wheel, ['/build/here', '/build/there/']) == [
        'a/b.txt: contains /build/here', 'c.so: contains /build/there']


@pytest.mark.parametrize('distro', DISTROS)
def test_the_wheel_depends_on_the_tested_ros_wheels(distro):
    pins = read_pins(ROOT / 'requirements' / f'{distro}.txt')
    requires = requires_dist(distro)
    for name in ('ros-rclpy', 'ros-rmw-fastrtps-cpp', 'ros-std-msgs', 'ros-std-srvs'):
        assert f'{name}=={pins[name]}' in requires
    assert f'numba~={pins["numba"]}' in requires
    # The build chain and the test tools are not the package's dependencies, nor are the
    # interface packages the wheel carries.
    assert not [r for r in requires if r.startswith(('ros-ament', 'ros-rosidl', 'pytest',
                                                     'ros-conveyor-twin-msgs',
                                                     'ros-simulation-interfaces'))]
