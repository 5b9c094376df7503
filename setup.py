"""Packaging of conveyor_twin: an ament_python package, also installable with pip."""

from glob import glob
from pathlib import Path
import re

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

PACKAGE_NAME = 'conveyor_twin'
#: The interface package conveyor_twin_msgs, whose .msg/.srv texts the recorder stores.
MSG_DEFS = Path(__file__).resolve().parent / 'msg_defs'
# The one place of the version: conveyor_twin/__init__.py (read, not imported).
VERSION = re.search(r"^__version__ = '([^']+)'$",
                    (Path(__file__).parent / PACKAGE_NAME / '__init__.py').read_text(),
                    re.M).group(1)



class BuildPy(build_py):
    """build_py that also copies msg_defs/msg/*.msg and msg_defs/srv/*.srv into the built
    package as conveyor_twin/wire/msg/conveyor_twin_msgs/ (conveyor_twin.wire.msg_files reads
    them there when installed; an editable install reads msg_defs/ itself)."""

    def run(self) -> None:
        super().run()
        if getattr(self, 'editable_mode', False):
            return
        target = Path(self.build_lib) / PACKAGE_NAME / 'wire' / 'msg' / 'conveyor_twin_msgs'
        for sub in ('msg', 'srv'):
            files = sorted((MSG_DEFS / sub).glob(f'*.{sub}'))
            if not files:
                raise SystemExit(f'setup.py: no *.{sub} files in {MSG_DEFS / sub}: the '
                                 'conveyor_twin_msgs sources (msg_defs/) must be next to setup.py')
            self.mkpath(str(target / sub))
            for path in files:
                self.copy_file(str(path), str(target / sub / path.name))


setup(
    name=PACKAGE_NAME,
    version=VERSION,
    packages=find_packages(exclude=['test', 'test.*']),
    # Files read at run time through importlib.resources (the embedded default cell), the example
    # cells, the PEP 561 marker and the .msg texts of the recorded standard types (BuildPy adds
    # those of msg_defs/).
    package_data={
        PACKAGE_NAME: ['py.typed'],
        f'{PACKAGE_NAME}.cell': ['*.yaml', 'examples/*.yaml'],
        f'{PACKAGE_NAME}.wire': ['msg/*/msg/*.msg'],
    },
    cmdclass={'build_py': BuildPy},
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE_NAME}']),
        (f'share/{PACKAGE_NAME}', ['package.xml']),
        (f'share/{PACKAGE_NAME}/cells', sorted(glob(f'{PACKAGE_NAME}/cell/*.yaml'))),
        (f'share/{PACKAGE_NAME}/cells/examples',
         sorted(glob(f'{PACKAGE_NAME}/cell/examples/*.yaml'))),
    ],
    install_requires=['setuptools'],
    # the PLC servers (conveyor-twin run --opcua / --modbus; docs/plc.md)
    extras_require={'plc': ['asyncua>=2.1,<3', 'pymodbus>=3.16,<4']},
    zip_safe=False,
    maintainer='conveyor_twin maintainers',
    maintainer_email='maintainers@conveyor-twin.org',
    description='Real-time digital twin of a conveyor cell (ROS 2)',
    license='Apache-2.0',
    python_requires='>=3.10',
    entry_points={
        'console_scripts': [
            'conveyor-twin = conveyor_twin.cli:main',
            'micro_simulator = conveyor_twin.ros.micro_node:main',
            'macro_simulator = conveyor_twin.ros.macro_node:main',
            'scale_coordinator = conveyor_twin.ros.split:coordinator_main',
        ],
        # pytest loads the fixtures of conveyor_twin.testing in every project that installs it.
        'pytest11': [
            'conveyor_twin = conveyor_twin.testing.plugin',
        ],
    },
)
