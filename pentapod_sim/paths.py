"""
Where the package's share files are: configuration, scenarios, launch files.

On an installed package (``colcon build`` on a ROS 2 install, or ``pip install``) the share
folder is found through the ament index (``ament_index_python``, which reads
``AMENT_PREFIX_PATH``), exactly as ``ros2 launch`` finds it. Code imported from a source
checkout (a ``package.xml`` beside the Python packages) uses the checkout's own folders, so an
edit of ``config/`` takes effect without reinstalling.
"""
from __future__ import annotations

from functools import lru_cache
import os
from pathlib import Path

from pentapod_sim.errors import ConfigError

PACKAGE = 'pentapod_testbed'


def _checkout_root() -> Path | None:
    """Root of the source checkout this module was imported from, if any."""
    root = Path(__file__).resolve().parent.parent
    return root if (root / 'package.xml').is_file() and (root / 'config').is_dir() else None


@lru_cache(maxsize=None)
def share_dir() -> Path:
    """
    Share folder of the package: the source checkout, else the ament index's.

    Raises
    ------
    ConfigError
        If neither exists; the message names ``AMENT_PREFIX_PATH`` and its value.
    """
    root = _checkout_root()
    if root is not None:
        return root
    try:
        from ament_index_python.packages import get_package_share_directory, PackageNotFoundError
    except ImportError:
        raise ConfigError('ament_index_python is not installed: cannot find the share '
                          f'folder of {PACKAGE}') from None
    try:
        return Path(get_package_share_directory(PACKAGE))
    except (PackageNotFoundError, LookupError, OSError, ValueError) as err:
        prefix = os.environ.get('AMENT_PREFIX_PATH', '')
        raise ConfigError(f'package {PACKAGE} is not in the ament index '
                          f'(AMENT_PREFIX_PATH={prefix!r}): {err}') from None


def config_dir() -> Path:
    """Folder of the configuration files (machine.yaml, positions.yaml, reduction.yaml, ...)."""
    path = share_dir() / 'config'
    if not (path / 'machine.yaml').is_file():
        raise ConfigError(f'no machine.yaml in {path}')
    return path


def scenario_dir() -> Path:
    """Folder of the shipped scenario files (``config/scenarios``)."""
    return share_dir() / 'config' / 'scenarios'


def launch_dir() -> Path:
    """Folder of the launch files."""
    return share_dir() / 'launch'
