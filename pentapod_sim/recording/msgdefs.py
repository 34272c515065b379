"""
Full ros2msg message definitions (with dependencies) for MCAP schemas, read from .msg files.

The text format is rosbag2's: the top-level .msg text, then for every (transitively) used
type a line of 80 '=' characters, a line ``MSG: pkg/msg/Type`` and that type's .msg text.
"""
import functools
import logging
import os
from pathlib import Path
import re
import sys

from pentapod_sim.errors import BagError

LOGGER = logging.getLogger(__name__)
SEPARATOR = '=' * 80
BUILTIN_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring',
})
_FIELD = re.compile(r'^\s*([A-Za-z][\w/]*)(?:<=\d+)?(?:\[[^\]]*\])?\s+(\w+)\s*(=)?')


def _share_dirs() -> list[Path]:
    """Candidate ``share`` folders: AMENT_PREFIX_PATH entries, then sys.prefix."""
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / 'share' for p in prefixes]


@functools.lru_cache(maxsize=None)
def msg_file_text(msg_type: str) -> str:
    """
    Return the text of the .msg file of ``pkg/msg/Type`` (or ``pkg/Type``).

    Raises
    ------
    BagError
        If no share folder holds the file (the message names the type and the folders).
    """
    pkg, name = _split_type(msg_type)
    tried = []
    for share in _share_dirs():
        path = share / pkg / 'msg' / f'{name}.msg'
        tried.append(str(path))
        if path.is_file():
            LOGGER.debug('message definition %s from %s', msg_type, path)
            return path.read_text(encoding='utf-8')
    raise BagError(f'no .msg file for type {msg_type!r}; looked in {tried}')


def _split_type(msg_type: str) -> tuple[str, str]:
    parts = msg_type.split('/')
    if len(parts) == 3 and parts[1] == 'msg':
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise BagError(f'message type {msg_type!r} is not of the form pkg/msg/Type')


def field_types(msg_text: str, package: str) -> list[str]:
    """
    List the non-builtin field types of a .msg text as ``pkg/msg/Type`` (constants skipped).

    Parameters
    ----------
    msg_text : str
        Content of a .msg file.
    package : str
        Package of that file (for types written without a package).

    Returns
    -------
    list of str
        Types in order of first use.
    """
    found = []
    for line in msg_text.splitlines():
        code = line.split('#', 1)[0]
        match = _FIELD.match(code)
        if not match or match.group(3):
            continue  # no field, or a constant definition
        base = match.group(1)
        if base in BUILTIN_TYPES:
            continue
        if '/' not in base:
            base = f'{package}/{base}'
        pkg, name = _split_type(base)
        full = f'{pkg}/msg/{name}'
        if full not in found:
            found.append(full)
    return found


@functools.lru_cache(maxsize=None)
def message_definition(msg_type: str) -> str:
    """
    Build the rosbag2 ``ros2msg`` schema text of ``pkg/msg/Type`` with all dependencies.

    Parameters
    ----------
    msg_type : str
        Type name, e.g. ``'sensor_msgs/msg/JointState'``.

    Returns
    -------
    str
        Definition text for an MCAP schema of encoding ``ros2msg``.
    """
    pkg, name = _split_type(msg_type)
    top = f'{pkg}/msg/{name}'
    ordered, stack = [], [top]
    while stack:  # depth-first, each dependency once
        current = stack.pop(0)
        if current in ordered:
            continue
        ordered.append(current)
        deps = field_types(msg_file_text(current), _split_type(current)[0])
        stack = [d for d in deps if d not in ordered] + stack
    text = msg_file_text(top).rstrip('\n')
    for dep in ordered[1:]:
        text += f'\n{SEPARATOR}\nMSG: {dep}\n' + msg_file_text(dep).rstrip('\n')
    return text + '\n'


def has_header_stamp(msg_type: str) -> bool:
    """
    Tell whether the first field of the type is a std_msgs/Header or builtin Time.

    Such messages start (after the 4-byte CDR encapsulation) with int32 sec, uint32 nanosec,
    which the recorder uses as log time.
    """
    pkg, _ = _split_type(msg_type)
    for line in msg_file_text(msg_type).splitlines():
        match = _FIELD.match(line.split('#', 1)[0])
        if match:
            first = match.group(1)
            if '/' not in first:
                first = f'{pkg}/{first}'
            return first in ('std_msgs/Header', 'std_msgs/msg/Header',
                             'builtin_interfaces/Time', 'builtin_interfaces/msg/Time')
    return False
