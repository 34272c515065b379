"""
Isolation of a testbed run: localhost-only discovery on a ROS domain no one else uses.

A ROS 2 Jazzy process that is told nothing discovers peers on its whole subnet on domain 0, so
any participant on the network could publish forces into a run. The scenario runner, the
launch file and the test session therefore set, unless the user already has:

* DDS on the loopback interface only (:mod:`pentapod_sim.scenario.network`: the package's
  Fast DDS profile and ``ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT``; a run the user opened
  to the network is refused unless opened explicitly);
* ``ROS_DOMAIN_ID`` = a domain that is free on this host, *reserved for the whole run*.

A free domain is one that (1) no other cooperating run holds and (2) no DDS participant on
this host is using now. (1) is a lock file per domain, ``<lock dir>/domain_<id>.lock``,
locked with ``fcntl.flock``: the lock belongs to the open file, so it is held as long as the
:class:`DomainLease` (or a process that inherited its file descriptor) lives, and the kernel
drops it when the holder exits, even by SIGKILL; there is nothing stale to clean up, and the
lock files are never deleted (deleting a lock file races with a process about to lock it).
(2) is checked after taking the lock: a Fast DDS participant binds the UDP port
``7400 + 250 d + 10 + 2 p`` (metatraffic unicast of participant ``p`` on domain ``d``, RTPS
default port mapping) without address reuse, so a port that cannot be bound means the domain
(or that port) is taken by someone who does not use these locks, e.g. a ``ros2 run`` started
by hand. Such a domain is skipped.

Why the holder of the lock is the run itself, not a helper that prints a number: a number
printed by a process that then exits is free again the moment it is printed. So:

* the scenario runner (:func:`pentapod_sim.scenario.runner.run_scenario`) holds a lease from
  before its first node starts until the last one has been stopped;
* the launch file holds one for the life of the ``ros2 launch`` process;
* the pytest session (conftest.py, used by tools/test.sh) holds one for the whole session and
  exports it, so every test's nodes (and runners started by tests) use it;
* each run of the study (tools/study.sh) goes through the runner and so holds its own;
* ``python -m pentapod_sim.scenario.domain COMMAND...`` runs any command (e.g. ``ros2 run``)
  with the variables set; it keeps the locked descriptor open across ``exec``, so the command
  itself holds the lease.

The domains handed out are 1-101: the ROS 2 documentation's safe range on Linux (the ports of
higher domains fall into the kernel's ephemeral port range 32768-60999), without 0, the
domain of every process that sets nothing. Lock folder: ``$PENTAPOD_DOMAIN_LOCK_DIR``, else
``<temp dir>/pentapod_ros_domains`` (shared by all users of the host: ports are host-wide).
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import os
from pathlib import Path
import socket
import sys
import tempfile
from typing import Iterable, Iterator, Mapping

from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.scenario.network import (
    check_environment,
    local_changes,
    RANGE_VAR,  # noqa: F401 (re-exported)
)

#: Domains handed out (inclusive): see the module docstring.
DOMAINS = range(1, 102)
#: Largest valid domain id (the RTPS ports of higher ones exceed 65535).
MAX_DOMAIN_ID = 232
#: Participants per domain whose discovery port is probed (a run of ours has about 5).
PROBED_PARTICIPANTS = 24
DOMAIN_VAR = 'ROS_DOMAIN_ID'
LOCK_DIR_VAR = 'PENTAPOD_DOMAIN_LOCK_DIR'


def lock_dir() -> Path:
    """Folder of the per-domain lock files (created world-writable with the sticky bit)."""
    path = Path(os.environ.get(LOCK_DIR_VAR) or Path(tempfile.gettempdir())
                / 'pentapod_ros_domains')
    if not path.is_dir():
        path.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(OSError):      # someone else's folder: keep its mode
            path.chmod(0o1777)
    return path


def discovery_port(domain: int, participant: int) -> int:
    """UDP metatraffic unicast port of ``participant`` on ``domain`` (RTPS default mapping)."""
    return 7400 + 250 * domain + 10 + 2 * participant


def domain_in_use(domain: int, participants: int = PROBED_PARTICIPANTS) -> bool:
    """Whether a DDS participant on this host (probably) uses ``domain`` now."""
    for participant in range(participants):
        port = discovery_port(domain, participant)
        if port > 65535:
            break
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(('', port))
            except OSError as err:
                if err.errno == errno.EADDRINUSE:
                    return True
                raise
    return False


class DomainLease:
    """
    A reserved ROS domain: the locked lock file, held until :meth:`release` or process exit.

    Use as a context manager, or keep the object alive as long as the domain is in use.
    """

    def __init__(self, domain: int, fd: int, path: Path):
        self.domain, self._fd, self.path = domain, fd, path

    @property
    def held(self) -> bool:
        """Whether this lease still holds its lock."""
        return self._fd is not None

    def keep_across_exec(self) -> None:
        """Let the lock survive ``os.exec*``: the new program holds the lease."""
        os.set_inheritable(self._fd, True)

    def release(self) -> None:
        """Free the domain (closing the descriptor drops the lock); idempotent."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> DomainLease:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def __repr__(self) -> str:
        return f'DomainLease(domain={self.domain}, held={self.held})'


def _try_lock(domain: int, folder: Path) -> DomainLease | None:
    path = folder / f'domain_{domain}.lock'
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
    except PermissionError:                     # another user's lock file: treat as taken
        return None
    with contextlib.suppress(OSError):          # lockable by every user (umask aside)
        os.fchmod(fd, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    with contextlib.suppress(OSError):          # who holds it, for a curious user
        os.ftruncate(fd, 0)
        os.pwrite(fd, f'{os.getpid()}\n'.encode(), 0)
    return DomainLease(domain, fd, path)


def allocate(domains: Iterable[int] = DOMAINS, folder: Path | None = None) -> DomainLease:
    """
    Reserve the first domain of ``domains`` that no lease holds and no participant uses.

    Raises
    ------
    RunError
        If every domain is taken; the message names the range and the lock folder.
    """
    folder = lock_dir() if folder is None else Path(folder)
    domains = list(domains)
    for domain in domains:
        lease = _try_lock(domain, folder)
        if lease is None:
            continue
        if domain_in_use(domain):               # probed only by the lock holder
            lease.release()
            continue
        return lease
    span = f'{domains[0]}-{domains[-1]}' if domains else 'an empty range'
    raise RunError(f'no free ROS domain in {span}: each is locked by another run (lock '
                   f'files in {folder}) or used by a DDS participant on this host; set '
                   f'{DOMAIN_VAR} to choose one')


def user_domain(env: Mapping[str, str]) -> int | None:
    """The ``ROS_DOMAIN_ID`` the user set in ``env`` (None if unset or empty)."""
    text = env.get(DOMAIN_VAR, '').strip()
    if not text:
        return None
    try:
        domain = int(text)
    except ValueError:
        domain = -1
    if not 0 <= domain <= MAX_DOMAIN_ID:
        raise ConfigError(f'{DOMAIN_VAR}={text!r} is not a ROS domain id (0-{MAX_DOMAIN_ID})')
    return domain


def isolation(env: Mapping[str, str], domain_id: int | str | None = None,
              domains: Iterable[int] = DOMAINS) -> tuple[dict[str, str], DomainLease | None]:
    """
    Variables to add to ``env`` so a run is isolated, and the lease reserving its domain.

    ``domain_id`` (e.g. ``--domain-id``) wins over ``env``. Local discovery (the default,
    LOCALHOST or OFF) gets the loopback-only DDS variables of
    :func:`pentapod_sim.scenario.network.local_changes`; a discovery range, static peers or a
    DDS profile the user chose is kept, and refused unless the network was opened explicitly.
    ``ROS_DOMAIN_ID`` set in ``env`` is kept (used even if another run holds it: the user chose
    it; locked if nobody does). The caller holds the returned lease, if any, for as long as the
    run lasts.

    Raises
    ------
    ConfigError
        If the chosen domain is not an integer in 0-232.
    RunError
        If no domain is free, or DDS would be open to the network without
        ``PENTAPOD_OPEN_NETWORK=1`` or SROS2
        (:func:`pentapod_sim.scenario.network.check_environment`).
    """
    changes = local_changes(env)
    check_environment({**env, **changes})
    if domain_id is not None:
        changes[DOMAIN_VAR] = str(domain_id).strip()
        chosen = user_domain(changes)
    else:
        chosen = user_domain(env)
    if chosen is None:
        lease = allocate(domains)
        changes[DOMAIN_VAR] = str(lease.domain)
    else:       # lock it if nobody does, so no allocation hands it out meanwhile
        lease = _try_lock(chosen, lock_dir())
    return changes, lease


@contextlib.contextmanager
def isolated_env(env: Mapping[str, str] | None = None,
                 domain_id: int | None = None) -> Iterator[dict[str, str]]:
    """
    The environment for a run's processes, with its domain reserved while the block runs.

    ``env`` defaults to ``os.environ``; ``domain_id`` wins over its ``ROS_DOMAIN_ID``.
    """
    env = dict(os.environ if env is None else env)
    changes, lease = isolation(env, domain_id)
    try:
        yield {**env, **changes}
    finally:
        if lease is not None:
            lease.release()


def main(argv: list[str] | None = None) -> int:
    """``python -m pentapod_sim.scenario.domain COMMAND [ARG...]``: run it isolated."""
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['--']:
        argv = argv[1:]
    if not argv or argv[0] in ('-h', '--help'):
        print('usage: python -m pentapod_sim.scenario.domain COMMAND [ARG...]\n\n'
              'Run COMMAND with DDS on the loopback interface only and a free\n'
              'ROS_DOMAIN_ID reserved for its lifetime (values already set are kept).')
        return 0 if argv else 2
    try:
        changes, lease = isolation(os.environ)
    except (ConfigError, RunError) as err:
        print(f'error: {err}', file=sys.stderr)
        return 1
    if lease is not None:
        lease.keep_across_exec()
    try:
        os.execvpe(argv[0], argv, {**os.environ, **changes})
    except OSError as err:
        print(f'error: cannot run {argv[0]!r}: {err.strerror}', file=sys.stderr)
        return 127


if __name__ == '__main__':
    raise SystemExit(main())
