"""Declared dependencies: each third-party import has a package.xml key; mcap stack pinned."""
import ast
from importlib import metadata
from pathlib import Path
import sys
import xml.etree.ElementTree as ET

from packaging.requirements import Requirement
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ('pentapod_sim', 'pentapod_damper')
#: Top-level import name -> package.xml key (rosdep key, or ``python3-<name>-pip`` where
#: rosdep has none, as the comments in package.xml say).
IMPORT_KEYS = {
    'ament_index_python': 'ament_index_python',
    'ansys': 'python3-ansys-mapdl-reader-pip',
    'builtin_interfaces': 'builtin_interfaces',
    'control': 'python-control-pip',
    'dask': 'python3-dask-pip',
    'distributed': 'python3-distributed-pip',
    'foxglove': 'python3-foxglove-sdk-pip',
    'primme': 'python3-primme-pip',
    'diagnostic_msgs': 'diagnostic_msgs',
    'geometry_msgs': 'geometry_msgs',
    'gmsh': 'python3-gmsh-pip',
    'skfem': 'python3-scikit-fem-pip',
    'lz4': 'python3-lz4-pip',
    'matplotlib': 'python3-matplotlib',
    'mcap': 'python3-mcap-pip',
    'mcap_ros2': 'mcap-ros2-support',
    'numpy': 'python3-numpy',
    'pyarrow': 'python3-pyarrow-pip',
    'pypardiso': 'python3-pypardiso-pip',
    'pyuff': 'python3-pyuff-pip',
    'rcl_interfaces': 'rcl_interfaces',
    'rclpy': 'rclpy',
    'rosgraph_msgs': 'rosgraph_msgs',
    'scipy': 'python3-scipy',
    'sensor_msgs': 'sensor_msgs',
    'std_msgs': 'std_msgs',
    'tqdm': 'python3-tqdm',
    'threadpoolctl': 'python3-threadpoolctl-pip',
    'yaml': 'python3-yaml',
    'zstandard': 'python3-zstandard-pip',
}
#: Distribution -> versions the tests ran with (requirements must admit them and pin a range).
PINNED = {'mcap': '1.6.0', 'mcap-ros2-support': '0.6.0', 'rosbags': '0.11.9'}


def third_party_imports(folder: Path) -> dict:
    """``{top-level name: first file:line}`` of every non-stdlib, non-project import below."""
    found: dict = {}
    for path in sorted(folder.rglob('*.py')):
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split('.')[0]
                if top not in sys.stdlib_module_names and top not in PACKAGES:
                    found.setdefault(top, f'{path.relative_to(folder.parent)}:{node.lineno}')
    return found


def _depends(kind: str) -> set:
    root = ET.parse(ROOT / 'package.xml').getroot()
    return {element.text.strip() for element in root.iter(kind)}


def test_every_third_party_import_has_a_package_xml_entry():
    runtime = _depends('exec_depend') | _depends('depend')
    missing = []
    for package in PACKAGES:
        for name, where in third_party_imports(ROOT / package).items():
            if name not in IMPORT_KEYS:
                missing.append(f'{where}: import {name} has no key in IMPORT_KEYS')
            elif IMPORT_KEYS[name] not in runtime:
                missing.append(f'{where}: import {name} needs <exec_depend>'
                               f'{IMPORT_KEYS[name]}</exec_depend>')
    assert missing == []


def test_the_import_walker_sees_local_and_from_imports(tmp_path):
    """The check can fail: a function-local import of an undeclared package is found."""
    package = tmp_path / 'pkg'
    package.mkdir()
    (package / 'm.py').write_text('import os\n\ndef f():\n    import foo_bar.baz\n'
                                  '    from spam.eggs import ham\n    from . import sibling\n')
    assert set(third_party_imports(package)) == {'foo_bar', 'spam'}


def _requirements(name: str) -> list:
    lines = (ROOT / name).read_text(encoding='utf-8').splitlines()
    return [Requirement(line) for line in lines if line and not line.startswith(('#', '-'))]


@pytest.mark.parametrize('distribution,tested', sorted(PINNED.items()))
def test_mcap_stack_is_pinned_to_the_tested_range(distribution, tested):
    requirements = {r.name: r for r in _requirements('requirements.txt')
                    + _requirements('requirements-dev.txt')}
    specifier = requirements[distribution].specifier
    assert specifier.contains(tested), f'{distribution} {specifier} excludes the tested {tested}'
    assert any(spec.operator in ('<', '==', '~=') for spec in specifier), \
        f'{distribution} {specifier} has no upper bound'
    installed = metadata.version(distribution)
    assert specifier.contains(installed), f'{distribution} {installed} not in {specifier}'
