"""A user's project outside this repository, run with this environment's pytest.

examples/user_project/ (a controller and its tests, nothing but the documented
``conveyor_twin.testing`` API and the installed pytest plugin) is copied into a temporary
directory and run by pytest as a child process, with two pytest-xdist workers: it passes from a
plain install, and its tests run side by side without seeing each other's traffic.
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
USER_PROJECT = Path(__file__).resolve().parents[2] / 'examples' / 'user_project'
RUN_TIMEOUT = 600.0  # [s]


def _run_pytest(directory: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop('PYTEST_ADDOPTS', None)
    env.pop('PYTEST_XDIST_WORKER', None)
    return subprocess.run([sys.executable, '-m', 'pytest', '-p', 'no:cacheprovider', *args],
                          cwd=directory, env=env, capture_output=True, text=True,
                          timeout=RUN_TIMEOUT, stdin=subprocess.DEVNULL)


def test_a_user_project_passes_with_two_workers(tmp_path):
    project = tmp_path / 'user_project'
    shutil.copytree(USER_PROJECT, project)
    result = _run_pytest(project, '-n', '2', '-q')
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert '3 passed' in result.stdout


FAILING_TEST = '''
import sys


def test_fails_with_a_controller_running(conveyor_twin):
    controller = conveyor_twin.start_controller(
        [sys.executable, '-c', 'import time; time.sleep(600)'])
    with open({pid_file!r}, 'w') as out:
        out.write(str(controller.pid))
    assert False, 'fails on purpose'
'''


def test_a_failing_user_test_leaves_no_process_behind(tmp_path):
    pid_file = tmp_path / 'controller.pid'
    project = tmp_path / 'failing'
    project.mkdir()
    (project / 'pytest.ini').write_text('[pytest]\n')
    (project / 'test_failing.py').write_text(FAILING_TEST.format(pid_file=str(pid_file)))
    result = _run_pytest(project, '-q')
    assert result.returncode == 1, result.stdout[-4000:]
    assert 'fails on purpose' in result.stdout
    pid = int(pid_file.read_text())
    assert not Path(f'/proc/{pid}').exists() or \
        Path(f'/proc/{pid}/stat').read_text().split()[2] == 'Z', f'controller {pid} still runs'
