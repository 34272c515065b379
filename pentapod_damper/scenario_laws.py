"""
Control laws of a scenario file, without ROS: what its damper and PMA nodes will run.

A scenario (config/scenarios/*.yaml) is a ROS 2 parameter file with one section per node.
This module reads the sections of the damper (``damper*``) and proof-mass actuator (``pma*``)
nodes and builds their laws with the nodes' own functions and defaults
(:mod:`pentapod_damper.node_parameters`), so offline models (analytic closed-loop FRFs, the
offline closed loop) and ROS runs of one scenario cannot drift apart.
"""
from __future__ import annotations

from typing import Any, Mapping

from pentapod_damper.node_parameters import damper_laws, pma_law
from pentapod_sim.errors import ConfigError
from pentapod_sim.scenario.files import executable_of


def scenario_laws(sections: Mapping[str, Mapping[str, Any]], dt: float) -> list:
    """
    All control laws of a scenario's nodes, in file order.

    Parameters
    ----------
    sections : mapping
        ``Scenario.sections`` of :func:`pentapod_sim.scenario.files.read_scenario`.
    dt : float
        Plant sample time [s] (the PMA integrates its proof mass with it, the dampers'
        filters and delays are discretised with it).
    """
    laws: list = []
    for name, params in sections.items():
        kind = executable_of(name)
        if kind == 'damper':
            laws += damper_laws(params, f'node {name!r}', dt).values()
        elif kind == 'pma':
            laws.append(pma_law(params, dt, f'node {name!r}'))
    return laws


def continuous_dampers(laws) -> dict[str, float]:
    """
    Equivalent viscous gains per input port: the ideal dampers the laws stand for.

    A viscous damper counts with its nominal ``b`` (its actuator/sensor dynamics left out: the
    continuous closed loop is the paper's ideal damper); an ideal PMA without filter or limits
    is the viscous damper ``b = m_a g`` on its mount.

    Raises
    ------
    ConfigError
        If a law has memory (a filtered or limited PMA): it has no viscous equivalent.
    """
    gains: dict[str, float] = {}
    for law in laws:
        viscous = getattr(law, 'viscous_gains', None)
        if viscous is not None:
            for port, b in zip(law.actuator_ports, viscous()):
                gains[port] = gains.get(port, 0.0) + float(b)
            continue
        k = law.linear_gain()
        if k is None:
            raise ConfigError(f'{type(law).__name__} on {law.actuator_ports} has a filter or '
                              'limits; it has no viscous equivalent')
        for i, port in enumerate(law.actuator_ports):
            gains[port] = gains.get(port, 0.0) - float(k[i, i])
    return gains


def viscous_equivalent(laws) -> dict[str, float] | None:
    """
    :func:`continuous_dampers` of the laws, or None if one of them has dynamics of its own.

    A law with a continuous model of its own (IFF, lag displacement, PPF, band-pass velocity)
    is not a viscous damper: its continuous reference is its own continuous loop
    (:func:`pentapod_damper.study.damping.continuous_loop_frf`).
    """
    if any(getattr(law, 'viscous_gains', None) is None and law.linear_gain() is None
           for law in laws):
        return None
    return continuous_dampers(laws)
