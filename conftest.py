"""
Pytest root configuration: tests import the package from this checkout.

The session runs isolated (pentapod_sim/scenario/domain.py): unless the caller set them,
DDS on the loopback interface only (the package's Fast DDS profile with
``ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT``, pentapod_sim/scenario/network.py) and a free
``ROS_DOMAIN_ID``, reserved by this pytest process until it exits, are put into the environment
before any test starts a node, so concurrent test runs, studies and users on this host never
share a domain, and nothing of a test listens on the network. In a parallel session (pytest -n,
tools/test.sh) each worker reserves a domain of its own.
"""
import os
import signal

import pytest

_LEASES = []


#: Set to the domain this session reserved, so that a parallel worker can tell it from a
#: domain its caller chose.
_SESSION_DOMAIN = 'PENTAPOD_TEST_SESSION_DOMAIN'


def pytest_configure(config):
    """Reserve the session's ROS domain and export the isolation variables."""
    from pentapod_sim.scenario.domain import DOMAIN_VAR, isolation
    if (os.environ.get('PYTEST_XDIST_WORKER')
            and os.environ.get(_SESSION_DOMAIN) == os.environ.get(DOMAIN_VAR)):
        # a worker of a parallel session (pytest -n) inherited the controller's domain: it
        # reserves its own, so that the two workers' runs never see each other's nodes
        os.environ.pop(DOMAIN_VAR, None)
    changes, lease = isolation(os.environ)
    os.environ.update(changes)
    if lease is not None:
        _LEASES.append(lease)
        os.environ[_SESSION_DOMAIN] = os.environ[DOMAIN_VAR]


def pytest_unconfigure(config):
    """Free the session's domain."""
    while _LEASES:
        _LEASES.pop().release()


def pytest_report_header(config):
    """Show the session's ROS domain."""
    held = ' (reserved for this session)' if _LEASES and _LEASES[0].held else ''
    return (f"ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID')}{held}, "
            f"ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')}, "
            f"FASTRTPS_DEFAULT_PROFILES_FILE={os.environ.get('FASTRTPS_DEFAULT_PROFILES_FILE')}")


@pytest.fixture(autouse=True)
def _stop_signal_handlers():
    """
    Give every test the stop-signal handlers the session started with.

    A command or node run in-process (``runner.main``, ``run_node``) installs
    :mod:`pentapod_sim.shutdown`'s handlers, which only record SIGTERM; a process forked
    later by another test (a multiprocessing pool's worker) inherited them, ignored the
    pool's SIGTERM at exit, and that test hung in ``Pool.terminate``.
    """
    from pentapod_sim.shutdown import STOP_SIGNALS
    saved = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)
