"""What a binary wheel of conveyor_twin declares: version, dependencies, tags.

The version is ``conveyor_twin.__version__`` with the ROS 2 distro as a local label
(``0.1.0+jazzy``): the wheels of both distros are the same project at the same release, built
against different ROS wheels. Dependencies come from the pinned requirements files: the ROS wheels
exactly as tested (the message package inside is built against them), the Python libraries as
compatible releases (``~=``) of the tested pins.
"""

from pathlib import Path
import re
from typing import Dict, List
import xml.etree.ElementTree as ET

ROOT = Path(__file__).resolve().parents[2]
DISTROS = ('jazzy', 'kilted')
#: manylinux tag of the ROS 2 wheels the wheel depends on (and the policy its libraries meet).
PLATFORM_TAG = 'manylinux_2_28_x86_64'
#: Python libraries the package imports at run time (requirements/common.txt has their pins).
RUNTIME_PYTHON = ('numpy', 'numba', 'mcap', 'mcap-ros2-support', 'PyYAML', 'foxglove-sdk')
#: Optional features: ``pip install 'conveyor_twin-...whl[plot]'``.
EXTRAS = {'plot': ('matplotlib',), 'bench': ('pymunk', 'websockets')}
#: The only RMW published as wheels; ros-rclpy does not pull it in.
RMW = 'ros-rmw-fastrtps-cpp'
MESSAGE_PACKAGE = 'conveyor_twin_msgs'
#: Interface packages built into the wheel (never dependencies): the twin's own messages and
#: simulation_interfaces, which has no PyPI wheel (interfaces/simulation_interfaces).
INTERFACE_PACKAGES = (MESSAGE_PACKAGE, 'simulation_interfaces')


def base_version() -> str:
    """Return ``__version__`` of conveyor_twin/__init__.py (read, not imported)."""
    text = (ROOT / 'conveyor_twin' / '__init__.py').read_text()
    match = re.search(r"^__version__ = '([^']+)'$", text, re.M)
    if not match:
        raise ValueError("conveyor_twin/__init__.py: no line __version__ = '<version>'")
    return match.group(1)


def wheel_version(distro: str) -> str:
    """Return the version of the wheel for ``distro``, e.g. ``0.1.0+jazzy``."""
    check_distro(distro)
    return f'{base_version()}+{distro}'


def check_distro(distro: str) -> None:
    """Raise ValueError unless ``distro`` is a supported ROS 2 distro."""
    if distro not in DISTROS:
        raise ValueError(f'distro {distro!r} is not supported; allowed: {", ".join(DISTROS)}')


def read_pins(path: Path) -> Dict[str, str]:
    """Return ``{normalised name: version}`` of the ``name==version`` lines of a requirements file,
    following ``-r`` includes."""
    pins: Dict[str, str] = {}
    for raw in path.read_text().splitlines():
        line = raw.split('#', 1)[0].strip()
        if not line:
            continue
        if line.startswith('-r '):
            pins.update(read_pins(path.parent / line[3:].strip()))
            continue
        name, sep, version = line.partition('==')
        if not sep:
            raise ValueError(f'{path}: {raw!r} is not pinned as name==version')
        pins[normalise(name)] = version.strip()
    return pins


def normalise(name: str) -> str:
    """Return the PEP 503 normalised form of a distribution name."""
    return re.sub(r'[-_.]+', '-', name).lower()


def ros_runtime_packages() -> List[str]:
    """Return the ROS wheels the package needs at run time: the ``exec_depend`` entries of
    package.xml that are ROS packages (the interface packages are inside the wheel), the
    ``depend`` entries of the interface packages it carries, and the RMW."""
    root = ET.parse(ROOT / 'package.xml').getroot()
    names = [e.text.strip() for e in root.findall('exec_depend') if e.text]
    for source in ('msg_defs', 'interfaces/simulation_interfaces'):
        carried = ET.parse(ROOT / source / 'package.xml').getroot()
        names += [e.text.strip() for e in carried.findall('depend') if e.text]
    wheels = ['ros-' + normalise(n) for n in names
              if not n.startswith('python3-') and n not in INTERFACE_PACKAGES]
    return sorted(set(wheels + [RMW]))


def requires_dist(distro: str) -> List[str]:
    """Return the ``Requires-Dist`` lines of the wheel for ``distro``."""
    check_distro(distro)
    path = ROOT / 'requirements' / f'{distro}.txt'
    pins = read_pins(path)

    def pin(name: str) -> str:
        try:
            return pins[normalise(name)]
        except KeyError:
            raise ValueError(f'{path}: no pin for {name} (the wheel depends on it)') from None

    lines = [f'{name}=={pin(name)}' for name in ros_runtime_packages()]
    lines += [f'{name}~={pin(name)}' for name in RUNTIME_PYTHON]
    for extra, names in EXTRAS.items():
        lines += [f'{name}~={pin(name)}; extra == "{extra}"' for name in names]
    return lines
