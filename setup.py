"""Packaging of the pentapod testbed (ament_python: builds with colcon and installs with pip)."""
from glob import glob
import os

from setuptools import find_packages, setup

PACKAGE = 'pentapod_testbed'

# One table for every executable: `ros2 run pentapod_testbed <name>`.
# Each entry is also shipped as the launcher `scripts/<name>` into lib/<package>/, because pip
# ignores setup.cfg's script_dir and `ros2 run` looks only there (test/test_packaging.py checks
# that both agree).
EXECUTABLES = {
    'recorder': 'pentapod_sim.nodes.recorder_node:main',
    'analyze': 'pentapod_sim.cli.analyze:main',
    'modes': 'pentapod_sim.cli.modes:main',
    'statespace': 'pentapod_sim.cli.statespace:main',
    'plant': 'pentapod_sim.nodes.plant_node:main',
    'exciter': 'pentapod_sim.nodes.exciter_node:main',
    'damper': 'pentapod_damper.nodes.damper_node:main',
    'pma': 'pentapod_damper.nodes.pma_node:main',
    'example_controller': 'pentapod_damper.nodes.example_controller:main',
    'scenario': 'pentapod_sim.scenario:main',
    'study': 'pentapod_sim.study.__main__:main',
}


def _files(pattern: str) -> list:
    return sorted(p for p in glob(pattern) if os.path.isfile(p))


setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench', 'bench.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', _files('config/*.yaml')),
        ('share/' + PACKAGE + '/config/scenarios', _files('config/scenarios/*.yaml')),
        ('share/' + PACKAGE + '/launch', _files('launch/*.launch.py')),
        ('lib/' + PACKAGE, ['scripts/' + name for name in EXECUTABLES]),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Pentapod testbed maintainers',
    maintainer_email='maintainers@pentapod-testbed.invalid',
    description='Virtual pentapod machine-tool testbed: FE model, modal plant, dampers, MCAP.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [f'{name} = {target}' for name, target in EXECUTABLES.items()],
    },
)
