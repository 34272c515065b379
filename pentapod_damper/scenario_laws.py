"""
Control laws of a scenario file, without ROS: what its damper and PMA nodes will run.

A scenario (config/scenarios/*.yaml) is a ROS 2 parameter file with one section per node.
This module reads the sections of the damper (``damper*``) and proof-mass actuator (``pma*``)
nodes and builds the same laws the nodes build, so offline models (analytic closed-loop FRFs,
the offline closed loop) and ROS runs of one scenario cannot drift apart.
"""
from __future__ import annotations

from typing import Any, Mapping

from pentapod_damper.laws import (
    ProofMassActuator,
    strut_axial_damper,
    strut_bending_damper,
    tcp_damper,
    ViscousDamper,
)
from pentapod_sim.errors import ConfigError

#: Defaults of the damper node's gains [N m s/rad, N s/m, N s/m] (same as the node's).
DAMPER_DEFAULTS = {'bending_gain': 1000.0, 'axial_gain': 50000.0, 'tcp_gain': 20000.0}
#: Defaults of the PMA node (same as the node's).
PMA_DEFAULTS = {'directions': ['x'], 'proof_mass': 5.0, 'gain': 4000.0, 'highpass_hz': 0.0,
                'stroke_limit': 0.0, 'force_limit': 0.0}


def damper_laws(params: Mapping[str, Any]) -> list[ViscousDamper]:
    """Viscous dampers of one damper node's parameters (see damper_node)."""
    gains = {key: float(params.get(key, default)) for key, default in DAMPER_DEFAULTS.items()}
    laws = []
    bending = [int(s) for s in params.get('bending_struts', []) if int(s)]
    axial = [int(s) for s in params.get('axial_struts', []) if int(s)]
    directions = [str(a) for a in params.get('tcp_directions', []) if a]
    if bending:
        laws.append(strut_bending_damper(bending, gains['bending_gain']))
    if axial:
        laws.append(strut_axial_damper(axial, gains['axial_gain']))
    if directions:
        laws.append(tcp_damper(directions, gains['tcp_gain']))
    return laws


def pma_law(params: Mapping[str, Any], dt: float) -> ProofMassActuator:
    """Proof-mass actuator of one PMA node's parameters at sample time ``dt`` [s]."""
    p = {**PMA_DEFAULTS, **params}
    return ProofMassActuator(list(p['directions']), float(p['proof_mass']), float(p['gain']),
                             dt, highpass_hz=float(p['highpass_hz']),
                             stroke_limit=float(p['stroke_limit']),
                             force_limit=float(p['force_limit']))


def scenario_laws(sections: Mapping[str, Mapping[str, Any]], dt: float) -> list:
    """
    All control laws of a scenario's nodes, in file order.

    Parameters
    ----------
    sections : mapping
        ``Scenario.sections`` of :func:`pentapod_sim.scenario.files.read_scenario`.
    dt : float
        Plant sample time [s] (the PMA integrates its proof mass with it).
    """
    laws: list = []
    for name, params in sections.items():
        if name.startswith('damper'):
            laws += damper_laws(params)
        elif name.startswith('pma'):
            laws.append(pma_law(params, dt))
    return laws


def continuous_dampers(laws) -> dict[str, float]:
    """
    Equivalent viscous gains per input port of memoryless linear laws.

    An ideal PMA without filter or limits is the viscous damper ``b = m_a g`` on its mount.

    Raises
    ------
    ConfigError
        If a law has memory (a filtered or limited PMA): it has no viscous equivalent.
    """
    gains: dict[str, float] = {}
    for law in laws:
        k = law.linear_gain()
        if k is None:
            raise ConfigError(f'{type(law).__name__} on {law.actuator_ports} has a filter or '
                              'limits; it has no viscous equivalent')
        for i, port in enumerate(law.actuator_ports):
            gains[port] = gains.get(port, 0.0) - float(k[i, i])
    return gains
