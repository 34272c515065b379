"""The package is a correct ament_python package: colcon builds it, ros2 run finds executables."""
from dataclasses import dataclass
import importlib
import os
from pathlib import Path
import runpy
import shutil
import subprocess
import sys
import sysconfig
import xml.etree.ElementTree as ET

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = 'pentapod_testbed'


def _executables() -> dict:
    """The executables, read like setup.py reads them (without importing the package)."""
    return runpy.run_path(str(ROOT / 'pentapod_sim' / 'registry.py'))['executables']()


def test_package_xml_is_format_3_ament_python():
    root = ET.parse(ROOT / 'package.xml').getroot()
    assert root.tag == 'package' and root.attrib['format'] == '3'
    assert root.findtext('name') == PACKAGE
    assert root.find('export').findtext('build_type') == 'ament_python'
    assert (ROOT / 'resource' / PACKAGE).is_file()


def test_every_executable_has_an_entry_point_and_every_node_kind_an_executable():
    from pentapod_sim.registry import executables, NODES
    assert executables() == _executables()
    assert {kind.name for kind in NODES} <= set(executables())
    for name, target in executables().items():
        module, func = target.split(':')
        assert callable(getattr(importlib.import_module(module), func)), name


def _clean_prefix(folder: Path) -> Path:
    """
    A Python prefix like a ROS install's /usr: the venv's libraries, no copy of the package.

    A virtual environment made from the venv's base interpreter, whose site-packages, lib/ and
    share/ link to every entry of the venv's except the package's own (bootstrap.sh installed
    it there). The ros wheels' bootstrapper (a .pth) then sets LD_LIBRARY_PATH from this
    prefix as it does for the venv. Returns the interpreter.
    """
    venv = Path(sys.prefix)
    subprocess.run([getattr(sys, '_base_executable', sys.executable), '-m', 'venv',
                    '--without-pip', str(folder)], check=True, timeout=120)
    site = Path(sysconfig.get_path('purelib'))
    ours = ('pentapod', '__editable__')

    def link_all(src: Path, dst: Path, skip=()):
        dst.mkdir(parents=True, exist_ok=True)
        for entry in src.iterdir():
            if entry.name not in skip and not entry.name.lower().startswith(ours) \
                    and not (dst / entry.name).exists():
                (dst / entry.name).symlink_to(entry)

    link_all(site, folder / site.relative_to(venv))
    link_all(venv / 'lib', folder / 'lib', skip=(site.parent.name, PACKAGE))
    link_all(venv / 'share', folder / 'share', skip=('ament_index', PACKAGE))
    for kind in (venv / 'share/ament_index/resource_index').iterdir():
        link_all(kind, folder / 'share/ament_index/resource_index' / kind.name, skip=(PACKAGE,))
    return folder / 'bin' / 'python'


@dataclass
class Install:
    """A colcon install space and the environment to run it in (see :func:`colcon_install`)."""

    base: Path                  # install base (holds setup.bash)
    prefix: Path                # install prefix of the package
    python: Path                # the clean interpreter colcon built with
    env: dict

    def run(self, *cmd, cwd: Path, extra_env=None, timeout: float = 300.0):
        """Run ``cmd`` after sourcing setup.bash, like a user of the install space."""
        return subprocess.run(['bash', '-c', 'source "$0/setup.bash" && exec "$@"',
                               str(self.base), *map(str, cmd)], cwd=cwd,
                              env={**self.env, **(extra_env or {})}, capture_output=True,
                              text=True, timeout=timeout)


@pytest.fixture(scope='module')
def colcon_install(tmp_path_factory) -> Install:
    """
    ``colcon build`` (no --symlink-install) of a copy of the checkout, once per module.

    colcon runs on a clean interpreter prefix (:func:`_clean_prefix`) as on a ROS install,
    so the launchers' shebangs name an interpreter without the package.
    """
    tmp = tmp_path_factory.mktemp('colcon')
    python = _clean_prefix(tmp / 'python')
    src = tmp / 'src' / PACKAGE
    files = subprocess.run(['git', 'ls-files', '--cached', '--others', '--exclude-standard'],
                           cwd=ROOT, check=True, capture_output=True, text=True).stdout.split()
    for rel in files:
        if (ROOT / rel).is_file():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, src / rel)
    env = {'PATH': f'{python.parent}:/usr/bin:/bin', 'HOME': str(tmp), 'LANG': 'C.UTF-8',
           'AMENT_PREFIX_PATH': str(python.parent.parent), 'PYTHONDONTWRITEBYTECODE': '1',
           'OPENBLAS_NUM_THREADS': '1', 'OMP_NUM_THREADS': '1', 'MPLBACKEND': 'Agg',
           'ROS_LOG_DIR': str(tmp / 'ros_log')}
    for name in ('TMPDIR', 'PENTAPOD_DOMAIN_LOCK_DIR'):    # the same domain lock folder
        if name in os.environ:
            env[name] = os.environ[name]
    proc = subprocess.run(
        [str(python), '-m', 'colcon', '--log-base', str(tmp / 'log'), 'build',
         '--base-paths', str(tmp / 'src'),
         '--build-base', str(tmp / 'build'), '--install-base', str(tmp / 'install')],
        cwd=tmp, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return Install(tmp / 'install', tmp / 'install' / PACKAGE, python, env)


@pytest.mark.slow
def test_colcon_builds_and_installs_executables_and_config(colcon_install):
    prefix = colcon_install.prefix
    assert (prefix / 'share/ament_index/resource_index/packages' / PACKAGE).is_file()
    assert (prefix / 'share' / PACKAGE / 'package.xml').is_file()
    assert list((prefix / 'share' / PACKAGE / 'config').glob('*.yaml'))
    for name in _executables():
        exe = prefix / 'lib' / PACKAGE / name
        assert exe.is_file() and os.access(exe, os.X_OK), f'{exe} missing'


INSTALLED_SCENARIO = """
/**:
  ros__parameters:
    sample_rate: 2000.0
plant:
  ros__parameters:
    position: P2
    steps: {steps}
    sources: [exciter]
    wait_for_subscribers: [recorder]
exciter:
  ros__parameters:
    kind: random
    amplitude: 10.0
    duration: {duration}
    wait_for_subscribers: [recorder]
recorder:
  ros__parameters:
    topics: {topics}
    output_dir: bags
    bag_name: installed
"""


@pytest.mark.slow
@pytest.mark.ros
def test_installed_package_runs_from_the_install_space(colcon_install, tmp_path):
    """
    Outside the checkout, with only the install space and the libraries: plant, runner, bag.

    The interpreter's prefix holds no copy of the package, so everything (code, config,
    scenarios) must come from the install space through PYTHONPATH and the ament index.
    """
    inst, cwd = colcon_install, tmp_path / 'elsewhere'
    cwd.mkdir()
    share = inst.prefix / 'share' / PACKAGE
    probe = inst.run(inst.python, '-c', (
        'import sys, pentapod_sim, pentapod_sim.paths as p; '
        'print(pentapod_sim.__file__); print(sys.prefix); print(p.share_dir()); '
        'print(p.config_dir())'), cwd=cwd)
    assert probe.returncode == 0, probe.stderr
    module, prefix, share_dir, config_dir = probe.stdout.split()
    assert Path(module).is_relative_to(inst.prefix / 'lib'), module
    assert Path(prefix) == inst.python.parent.parent
    site = Path(prefix) / Path(sysconfig.get_path('purelib')).relative_to(sys.prefix)
    assert site.is_dir() and not list(site.glob('pentapod*')), 'the package is in the prefix'
    assert not (Path(prefix) / 'lib' / PACKAGE).exists()
    assert not (Path(prefix) / 'share' / PACKAGE).exists()
    assert Path(share_dir) == share and Path(config_dir) == share / 'config'
    assert not Path(module).is_relative_to(ROOT)

    lib = inst.prefix / 'lib' / PACKAGE
    ros = {'ROS_DOMAIN_ID': os.environ['ROS_DOMAIN_ID'],       # the session's (conftest.py)
           'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    plant = inst.run(lib / 'plant', '--ros-args', '-p', 'position:=P2', '-p', 'steps:=20',
                     '-p', 'output_file:=plant.npz', cwd=cwd, extra_env=ros)
    assert plant.returncode == 0, plant.stdout + plant.stderr
    trace = np.load(cwd / 'plant.npz')
    assert trace['y'].shape[0] == 20 and trace['u'].shape[0] == 20
    assert list((cwd / 'out' / 'models').glob('plant_P2_*.npz')), 'P2 built from share config'

    listing = inst.run(lib / 'scenario', 'baseline', '--list', cwd=cwd)
    assert listing.returncode == 0, listing.stderr
    assert 'plant: plant' in listing.stdout and 'exciter: exciter' in listing.stdout

    steps = 200
    topics = ['/clock', '/pentapod/tcp_state', '/pentapod/excitation', '/pentapod/forces/exciter']
    (cwd / 'scenario.yaml').write_text(INSTALLED_SCENARIO.format(
        steps=steps, duration=steps / 2000.0, topics=topics))
    run = inst.run(lib / 'scenario', 'scenario.yaml', '--timeout', '240', cwd=cwd)
    assert run.returncode == 0, run.stdout + run.stderr
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT' in run.stdout + run.stderr  # isolated
    assert (share / 'config' / 'dds' / 'loopback.xml').is_file()    # its DDS profile
    info = inst.run(lib / 'analyze', 'info', cwd / 'bags' / 'installed', cwd=cwd)
    assert info.returncode == 0, info.stdout + info.stderr
    counts = {line.split()[0]: int(line.split()[2]) for line in info.stdout.splitlines()
              if ' msgs ' in line}
    assert counts == dict.fromkeys(topics, steps), info.stdout


def test_pip_install_puts_launchers_where_ros2_run_looks():
    """tools/bootstrap.sh installs the package into the venv; ros2 run looks in lib/<pkg>."""
    from ament_index_python.packages import get_package_prefix
    prefix = Path(get_package_prefix(PACKAGE))
    assert prefix == Path(sys.prefix)
    for name in _executables():
        assert os.access(prefix / 'lib' / PACKAGE / name, os.X_OK), name
