"""Packaging of conveyor_twin: an ament_python package, also installable with pip."""

from glob import glob
from pathlib import Path
import re

from setuptools import find_packages, setup

PACKAGE_NAME = 'conveyor_twin'
# The one place of the version: conveyor_twin/__init__.py (read, not imported).
VERSION = re.search(r"^__version__ = '([^']+)'$",
                    (Path(__file__).parent / PACKAGE_NAME / '__init__.py').read_text(),
                    re.M).group(1)

setup(
    name=PACKAGE_NAME,
    version=VERSION,
    packages=find_packages(exclude=['test', 'test.*']),
    # Files read at run time through importlib.resources (the embedded default cell), the example
    # cells and the PEP 561 marker.
    package_data={
        PACKAGE_NAME: ['py.typed'],
        f'{PACKAGE_NAME}.cell': ['*.yaml', 'examples/*.yaml'],
    },
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE_NAME}']),
        (f'share/{PACKAGE_NAME}', ['package.xml']),
        (f'share/{PACKAGE_NAME}/cells', sorted(glob(f'{PACKAGE_NAME}/cell/*.yaml'))),
        (f'share/{PACKAGE_NAME}/cells/examples',
         sorted(glob(f'{PACKAGE_NAME}/cell/examples/*.yaml'))),
    ],
    install_requires=['setuptools'],
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
