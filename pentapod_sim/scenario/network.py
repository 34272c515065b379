"""
DDS on the loopback interface unless the user opens the network (docs/nodes.md, "Isolation").

``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` keeps *discovery* on this host, but not the sockets:
with the Fast DDS wheels of Jazzy (rmw_fastrtps_cpp 8.4.3, Fast DDS 2.14.5) every process still
binds UDP ports on 0.0.0.0 and one on each interface's address, because the RMW appends a UDPv4
transport of its own for LOCALHOST, whatever a profile says. So a local run here means:

* ``FASTRTPS_DEFAULT_PROFILES_FILE`` = the package's ``config/dds/loopback.xml`` (one UDPv4
  transport allowed on 127.0.0.1, unicast discovery to 127.0.0.1, no built-in transports);
* ``ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT``, so the RMW adds nothing to the profile
  (and ``ROS_LOCALHOST_ONLY=0`` if it was 1, which would mean LOCALHOST again).

:func:`local_changes` gives these variables when discovery is local: the range unset (the
project's default), LOCALHOST or OFF, or the deprecated ``ROS_LOCALHOST_ONLY=1``, with no
``ROS_STATIC_PEERS``, no DDS profile of the user's and the Fast DDS RMW. The scenario runner,
the launch file, the study and the tests (:func:`pentapod_sim.scenario.domain.isolation`),
tools/env.sh (``python -m pentapod_sim.scenario.network``) and every node started with
``ros2 run`` (:func:`prepare_process`) apply them.

Anything else opens DDS to the networks of this host: a range SUBNET or SYSTEM_DEFAULT without
this profile, static peers, a profile of the user's, another RMW (whose binding is not
checked here). :func:`check_environment` refuses such a run before it starts, and
:func:`check_sockets` refuses a node whose own UDP sockets are bound outside 127.0.0.0/8 and
::1 (e.g. a profile that failed to parse, which Fast DDS only logs), unless the user opened
the network explicitly: ``PENTAPOD_OPEN_NETWORK=1``, or SROS2 enforced
(``ROS_SECURITY_ENABLE=true`` and ``ROS_SECURITY_STRATEGY=Enforce``; the Fast DDS wheels have
no security libraries, so that needs a ROS 2 install whose Fast DDS has them).
"""
from __future__ import annotations

from dataclasses import dataclass
import ipaddress
import os
from pathlib import Path
import shlex
import sys
from typing import Mapping, MutableMapping

from pentapod_sim.errors import RunError
from pentapod_sim.paths import share_dir

RANGE_VAR = 'ROS_AUTOMATIC_DISCOVERY_RANGE'
#: Deprecated predecessor of ``ROS_AUTOMATIC_DISCOVERY_RANGE``; ``1`` means LOCALHOST.
LOCALHOST_ONLY_VAR = 'ROS_LOCALHOST_ONLY'
STATIC_PEERS_VAR = 'ROS_STATIC_PEERS'
#: Fast DDS reads its XML profile from the first (2.x, Jazzy) or the second (3.x).
PROFILE_VARS = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
#: ``1`` (or true/yes): run open on the network without SROS2, knowingly.
OPEN_VAR = 'PENTAPOD_OPEN_NETWORK'
#: RMW implementations the loopback profile applies to ('' = the default, Fast DDS).
FAST_DDS_RMWS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')
#: Discovery ranges that keep a run on this host (and the unset one: the project's default).
LOCAL_RANGES = ('', 'LOCALHOST', 'OFF')
#: The range set with the profile: the RMW leaves the profile's transports alone.
PROFILE_RANGE = 'SYSTEM_DEFAULT'
PROFILE_FILE = Path('config', 'dds', 'loopback.xml')


def loopback_profile() -> Path:
    """The installed Fast DDS profile of a local run (found through the ament index)."""
    return share_dir() / PROFILE_FILE


def _value(env: Mapping[str, str], name: str) -> str:
    return env.get(name, '').strip()


def _truthy(text: str) -> bool:
    return text.strip().lower() in ('1', 'true', 'yes', 'on')


def _user_profile(env: Mapping[str, str]) -> str:
    return next((_value(env, v) for v in PROFILE_VARS if _value(env, v)), '')


def uses_loopback_profile(env: Mapping[str, str]) -> bool:
    """Whether the profile variable of ``env`` names a copy of :func:`loopback_profile`."""
    path = _user_profile(env)
    if not path:
        return False
    try:
        return Path(path).read_bytes() == loopback_profile().read_bytes()
    except OSError:
        return False


def local_changes(env: Mapping[str, str]) -> dict[str, str]:
    """
    Variables to add to ``env`` so DDS binds the loopback interface only (see the module doc).

    Empty if ``env`` already runs so, or opens the network (range SUBNET or SYSTEM_DEFAULT,
    static peers, a DDS profile of the user's); for another RMW than Fast DDS only an unset
    range becomes LOCALHOST.
    """
    rng, only = _value(env, RANGE_VAR).upper(), _value(env, LOCALHOST_ONLY_VAR)
    local = rng in LOCAL_RANGES if only != '1' else rng in ('', 'LOCALHOST')
    if not local or _value(env, STATIC_PEERS_VAR):
        return {}
    if _value(env, 'RMW_IMPLEMENTATION') not in FAST_DDS_RMWS:
        return {} if rng or only else {RANGE_VAR: 'LOCALHOST'}
    if not _user_profile(env):
        changes = {PROFILE_VARS[0]: str(loopback_profile())}
    elif uses_loopback_profile(env):    # e.g. exported by tools/env.sh, LOCALHOST set later
        changes = {}
    else:                               # the user's own profile: theirs to answer for
        return {}
    changes[RANGE_VAR] = 'OFF' if rng == 'OFF' else PROFILE_RANGE
    if only == '1':
        changes[LOCALHOST_ONLY_VAR] = '0'
    return {k: v for k, v in changes.items() if _value(env, k) != v}


def opened_explicitly(env: Mapping[str, str]) -> bool:
    """``PENTAPOD_OPEN_NETWORK`` set true, or SROS2 enforced (ROS_SECURITY_*)."""
    return _truthy(_value(env, OPEN_VAR)) or (
        _truthy(_value(env, 'ROS_SECURITY_ENABLE'))
        and _value(env, 'ROS_SECURITY_STRATEGY').lower() == 'enforce')


def exposure(env: Mapping[str, str]) -> str:
    """Why DDS in ``env`` would reach beyond this host ('' if it stays on the loopback)."""
    rmw = _value(env, 'RMW_IMPLEMENTATION')
    rng = _value(env, RANGE_VAR).upper() or ('LOCALHOST' if _value(env, LOCALHOST_ONLY_VAR)
                                             == '1' else '(unset: SUBNET)')
    peers = _value(env, STATIC_PEERS_VAR)
    if peers:
        return f'{STATIC_PEERS_VAR}={peers!r} names peers on the network'
    if rmw not in FAST_DDS_RMWS:        # not checked here: trust the RMW with LOCALHOST
        return '' if rng == 'LOCALHOST' else f'{RANGE_VAR}={rng} with {rmw}'
    if uses_loopback_profile(env):
        if rng == 'LOCALHOST':
            return (f'{RANGE_VAR}=LOCALHOST makes {rmw or "rmw_fastrtps_cpp"} add a UDPv4 '
                    f'transport on every interface to the loopback profile (use '
                    f'{PROFILE_RANGE})')
        return ''
    profile = _user_profile(env)
    if profile:
        return f'the DDS profile {profile} is not the loopback profile {loopback_profile()}'
    return f'{RANGE_VAR}={rng} without the loopback profile binds every interface'


def check_environment(env: Mapping[str, str]) -> None:
    """
    Refuse a run whose DDS would reach the network unless it was opened explicitly.

    Raises
    ------
    RunError
        One line: why the run is open, and the two ways to proceed.
    """
    why = exposure(env)
    if why and not opened_explicitly(env):
        raise RunError(f'DDS would be open to the network: {why}; and SROS2 is not enforced. '
                       f'Unset {RANGE_VAR} for a run on this host only, or set {OPEN_VAR}=1 '
                       'to run open anyway (docs/nodes.md, "Isolation and networks")')


def prepare_process(environ: MutableMapping[str, str] | None = None) -> None:
    """
    Confine this process's DDS to the loopback (:func:`local_changes`), or check it was opened.

    Call before ``rclpy.init``: rcl and Fast DDS read these variables when the first context
    and participant are made. ``environ`` defaults to ``os.environ``.
    """
    environ = os.environ if environ is None else environ
    environ.update(local_changes(environ))
    check_environment(environ)


@dataclass(frozen=True)
class Socket:
    """An internet socket of a process: protocol, local address and port, kernel inode."""

    protocol: str
    address: str
    port: int
    inode: int

    @property
    def loopback(self) -> bool:
        """Bound to 127.0.0.0/8 or ::1 (0.0.0.0, :: and other addresses are not)."""
        address = ipaddress.ip_address(self.address)
        mapped = getattr(address, 'ipv4_mapped', None)
        return (mapped or address).is_loopback

    def __str__(self) -> str:
        host = f'[{self.address}]' if ':' in self.address else self.address
        return f'{host}:{self.port}/{self.protocol}'


def _address(hex_address: str) -> str:
    raw = bytes.fromhex(hex_address)
    if len(raw) == 4:
        return str(ipaddress.IPv4Address(raw[::-1]))
    words = b''.join(raw[i:i + 4][::-1] for i in range(0, 16, 4))   # four host-order words
    return str(ipaddress.IPv6Address(words))


def process_sockets(pid: int | str = 'self',
                    protocols: tuple[str, ...] = ('udp', 'udp6', 'tcp', 'tcp6')) -> list[Socket]:
    """
    The internet sockets a process holds open (Linux: /proc; empty elsewhere).

    Reads the socket tables of the process's network namespace (``/proc/PID/net/udp`` ...) and
    keeps the sockets whose inode is one of the process's descriptors (``/proc/PID/fd``).
    """
    proc = Path('/proc') / str(pid)
    inodes = set()
    try:
        for link in (proc / 'fd').iterdir():
            try:
                target = os.readlink(link)
            except OSError:             # closed meanwhile
                continue
            if target.startswith('socket:['):
                inodes.add(int(target[8:-1]))
    except OSError:
        return []
    found = []
    for protocol in protocols:
        try:
            lines = (proc / 'net' / protocol).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            inode = int(fields[9])
            if inode in inodes:
                host, port = fields[1].split(':')
                found.append(Socket(protocol, _address(host), int(port, 16), inode))
    return found


def check_sockets(pid: int | str = 'self', env: Mapping[str, str] | None = None) -> None:
    """
    Refuse a process whose UDP sockets (DDS) are bound outside the loopback, unless opened.

    Raises
    ------
    RunError
        Naming the sockets, if any is bound elsewhere and ``env`` (default ``os.environ``)
        did not open the network explicitly.
    """
    env = os.environ if env is None else env
    if opened_explicitly(env):
        return
    bad = [s for s in process_sockets(pid, ('udp', 'udp6')) if not s.loopback]
    if bad:
        why = exposure(env) or 'the loopback profile did not take effect'
        raise RunError(f'DDS socket(s) bound outside the loopback interface: '
                       f'{", ".join(sorted(map(str, bad)))} ({why}); set {OPEN_VAR}=1 to run '
                       'open anyway (docs/nodes.md, "Isolation and networks")')


def main(argv: list[str] | None = None) -> int:
    """``python -m pentapod_sim.scenario.network``: the export lines of a local shell."""
    argv = sys.argv[1:] if argv is None else argv
    if argv:
        print('usage: python -m pentapod_sim.scenario.network\n\nPrint the shell exports '
              'that keep DDS on the loopback interface (tools/env.sh evaluates them).')
        return 0 if argv[0] in ('-h', '--help') else 2
    for name, value in local_changes(os.environ).items():
        print(f'export {name}={shlex.quote(value)}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
