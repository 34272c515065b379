"""Packaging of the pentapod testbed (ament_python: builds with colcon and installs with pip)."""
from glob import glob
import os
import runpy

from setuptools import find_packages, setup

PACKAGE = 'pentapod_testbed'
HERE = os.path.dirname(os.path.abspath(__file__))

# The nodes and commands are listed once, in pentapod_sim/registry.py (read here without
# importing the package). Each also gets a launcher in lib/<package>/ made at build time:
# `ros2 run` looks only there, and pip ignores setup.cfg's script_dir (colcon honours it).
EXECUTABLES = runpy.run_path(os.path.join(HERE, 'pentapod_sim', 'registry.py'))['executables']()
LAUNCHER = """#!/usr/bin/env python3
\"\"\"Launcher of `ros2 run {package} {name}`.\"\"\"
import sys

from {module} import {function}

sys.exit({function}())
"""


def _launchers() -> list:
    """Write one launcher per executable into build/launchers; return their relative paths."""
    folder = os.path.join('build', 'launchers')     # relative: colcon requires it
    os.makedirs(os.path.join(HERE, folder), exist_ok=True)
    paths = []
    for name, target in EXECUTABLES.items():
        module, function = target.split(':')
        path = os.path.join(folder, name)
        with open(os.path.join(HERE, path), 'w', encoding='utf-8') as stream:
            stream.write(LAUNCHER.format(package=PACKAGE, name=name, module=module,
                                         function=function))
        os.chmod(os.path.join(HERE, path), 0o755)
        paths.append(path)
    return paths


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
        ('share/' + PACKAGE + '/config/foxglove', _files('config/foxglove/*.json')),
        ('share/' + PACKAGE + '/config/dds', _files('config/dds/*.xml')),
        ('share/' + PACKAGE + '/launch', _files('launch/*.launch.py')),
        ('lib/' + PACKAGE, _launchers()),
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
