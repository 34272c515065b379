"""The package is a correct ament_python package: colcon builds it, ros2 run finds executables."""
import importlib
import os
from pathlib import Path
import runpy
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = 'pentapod_testbed'


def _executables() -> dict:
    """The executables table, read like setup.py reads it (without importing the package)."""
    return runpy.run_path(str(ROOT / 'pentapod_sim' / 'executables.py'))['EXECUTABLES']


def test_package_xml_is_format_3_ament_python():
    root = ET.parse(ROOT / 'package.xml').getroot()
    assert root.tag == 'package' and root.attrib['format'] == '3'
    assert root.findtext('name') == PACKAGE
    assert root.find('export').findtext('build_type') == 'ament_python'
    assert (ROOT / 'resource' / PACKAGE).is_file()


def test_every_executable_has_an_entry_point_and_every_node_kind_an_executable():
    from pentapod_sim.executables import EXECUTABLES, NODE_KINDS
    assert EXECUTABLES == _executables()
    assert set(NODE_KINDS) <= set(EXECUTABLES)
    for name, target in EXECUTABLES.items():
        module, func = target.split(':')
        assert callable(getattr(importlib.import_module(module), func)), name


@pytest.mark.slow
def test_colcon_builds_and_installs_executables_and_config(tmp_path):
    colcon = shutil.which('colcon')
    assert colcon, 'colcon is installed by tools/bootstrap.sh'
    src = tmp_path / 'src' / PACKAGE
    files = subprocess.run(['git', 'ls-files', '--cached', '--others', '--exclude-standard'],
                           cwd=ROOT, check=True, capture_output=True, text=True).stdout.split()
    for rel in files:
        if (ROOT / rel).is_file():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, src / rel)
    proc = subprocess.run(
        [colcon, '--log-base', str(tmp_path / 'log'), 'build',
         '--base-paths', str(tmp_path / 'src'),
         '--build-base', str(tmp_path / 'build'), '--install-base', str(tmp_path / 'install')],
        cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    prefix = tmp_path / 'install' / PACKAGE
    assert (prefix / 'share/ament_index/resource_index/packages' / PACKAGE).is_file()
    assert (prefix / 'share' / PACKAGE / 'package.xml').is_file()
    assert list((prefix / 'share' / PACKAGE / 'config').glob('*.yaml'))
    for name in _executables():
        exe = prefix / 'lib' / PACKAGE / name
        assert exe.is_file() and os.access(exe, os.X_OK), f'{exe} missing'


def test_pip_install_puts_launchers_where_ros2_run_looks():
    """tools/bootstrap.sh installs the package into the venv; ros2 run looks in lib/<pkg>."""
    from ament_index_python.packages import get_package_prefix
    prefix = Path(get_package_prefix(PACKAGE))
    assert prefix == Path(sys.prefix)
    for name in _executables():
        assert os.access(prefix / 'lib' / PACKAGE / name, os.X_OK), name
