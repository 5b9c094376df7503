"""One version: ``conveyor_twin.__version__``, reported everywhere the product states it."""

from pathlib import Path
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from conveyor_twin import __version__
from conveyor_twin.cli import main
from conveyor_twin.record.writer import LIBRARY

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize('package_xml', ['package.xml', 'msg_defs/package.xml'])
def test_the_ros_packages_carry_the_version(package_xml):
    assert ET.parse(ROOT / package_xml).getroot().findtext('version') == __version__


def test_setup_py_reads_the_version():
    result = subprocess.run([sys.executable, 'setup.py', '--version'], cwd=ROOT, text=True,
                            capture_output=True, stdin=subprocess.DEVNULL, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines()[-1] == __version__


def test_the_changelog_has_the_version():
    changelog = (ROOT / 'CHANGELOG.md').read_text()
    assert re.search(rf'^## \[{re.escape(__version__)}\] - \d{{4}}-\d{{2}}-\d{{2}}$', changelog,
                     re.M), f'CHANGELOG.md has no section "## [{__version__}] - YYYY-MM-DD"'


@pytest.mark.parametrize('flag', ['--version', '-V'])
def test_the_command_prints_the_version(flag, capsys):
    assert main([flag]) == 0
    assert capsys.readouterr().out == f'conveyor-twin {__version__}\n'


def test_recordings_name_the_version():
    assert LIBRARY.startswith(f'conveyor_twin/{__version__} ')


@pytest.mark.ros
def test_the_nodes_report_the_version(ros_context):
    from rclpy.node import Node

    from conveyor_twin.ros.params import declare_twin_parameters

    node = Node('version_probe', context=ros_context)
    try:
        declare_twin_parameters(node)
        assert node.get_parameter('version').value == __version__
        assert node.describe_parameter('version').read_only
    finally:
        node.destroy_node()
