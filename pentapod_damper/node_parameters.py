"""
Parameters of the damper, PMA and example-controller nodes, and the laws they configure.

The one home of the laws' defaults, ranges and construction: the nodes
(:mod:`pentapod_damper.nodes`) declare their parameters from these classes and build their laws
with :meth:`DamperParams.laws` and :meth:`PmaParams.law`; the offline equivalents of a scenario
(:mod:`pentapod_damper.scenario_laws`, the study) build the same from the scenario file's
sections (:func:`damper_laws`, :func:`pma_law`). ROS-free.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from pentapod_damper.laws import (
    chord_damper,
    Dynamics,
    ProofMassActuator,
    strut_axial_damper,
    strut_bending_damper,
    tcp_damper,
    ViscousDamper,
)
from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import NodeParams, param, Sampled, SourceParams

#: Upper bound of the damper gains.
MAX_GAIN = 1.0e9


@dataclass(frozen=True)
class DynamicsParams(NodeParams):
    """The actuator/sensor dynamics of a law (:class:`pentapod_damper.laws.Dynamics`)."""

    filter_order: int = param(0, 'low-pass between velocity sensor and actuator force: 0 = '
                              'none, 1 = first order, 2 = second order', bounds=(0, 2))
    bandwidth_hz: float = param(0.0, 'corner frequency of the low-pass (below Nyquist)', 'Hz',
                                bounds=(0.0, 1.0e6))
    filter_damping: float = param(0.7071067811865476, 'damping ratio of the second-order '
                                  'low-pass', bounds=(1.0e-3, 10.0))
    filter_hold: str = param('foh', "input assumption of the filter's exact discretisation: "
                             'foh = sensor signal linear between samples, zoh = held over each '
                             'step (one more sample of lag)', choices=('foh', 'zoh'))
    delay_steps: int = param(0, 'pure delay of the force in samples: 0 = sampled feedback with '
                             'zero-order hold (u_k answers y_k), 1 = one-sample computational '
                             'delay', 'samples', bounds=(0, 1000))

    def dynamics(self) -> Dynamics:
        """The law's dynamics (ConfigError for a combination the law refuses)."""
        return Dynamics(self.filter_order, self.bandwidth_hz, self.filter_damping,
                        self.delay_steps, self.filter_hold)


@dataclass(frozen=True)
class DamperParams(Sampled, DynamicsParams, SourceParams):
    """
    Viscous velocity feedback u = -b * rate on struts and the TCP.

    Optionally through a low-pass and a delay (the same for every damper of the node); the
    gains may be changed while running.
    """

    bending_struts: tuple[int, ...] = param((), 'struts (1..5) with rotational bending dampers '
                                            'on both cardan axes (end-rotation difference); [] '
                                            'or [0] = none')
    bending_gain: float = param(1000.0, 'bending damping b of each strut and cardan axis',
                                'N m s/rad', bounds=(0.0, MAX_GAIN), read_only=False)
    chord_struts: tuple[int, ...] = param((), 'struts (1..5) with translational chord dampers '
                                          'along e2 and e3 at the chord point '
                                          '(config/reduction.yaml chord_position, default '
                                          'mid-span) against the chord between the joints; [] '
                                          'or [0] = none')
    chord_gain: float = param(20000.0, 'chord damping b of each strut and direction', 'N s/m',
                              bounds=(0.0, MAX_GAIN), read_only=False)
    axial_struts: tuple[int, ...] = param((), 'struts (1..5) with axial dampers between strut '
                                          'and BP ring')
    axial_gain: float = param(50000.0, 'axial damping b', 'N s/m', bounds=(0.0, MAX_GAIN),
                              read_only=False)
    tcp_directions: tuple[str, ...] = param((), 'directions (x, y, z) of dampers from the TCP '
                                            'to ground')
    tcp_gain: float = param(20000.0, 'TCP damping b', 'N s/m', bounds=(0.0, MAX_GAIN),
                            read_only=False)

    def laws(self, source: str = '', dt: float | None = None) -> dict[str, ViscousDamper]:
        """
        The viscous dampers of the node, keyed by the name of their gain parameter.

        ``bending_gain``, ``chord_gain``, ``axial_gain``, ``tcp_gain`` -> law, for the dampers
        configured, in this order (the order of the node's actuator ports); their dynamics
        are discretised with ``dt`` [s] (default :attr:`dt`). ConfigError (naming ``source``)
        for dynamics the laws refuse.
        """
        try:
            dyn = self.dynamics()
        except ConfigError as err:
            raise ConfigError(f'{source}: {err}' if source else str(err)) from None
        step = self.dt if dt is None else dt
        laws = {}
        if self.bending_struts:
            laws['bending_gain'] = strut_bending_damper(list(self.bending_struts),
                                                        self.bending_gain, dyn, step)
        if self.chord_struts:
            laws['chord_gain'] = chord_damper(list(self.chord_struts), self.chord_gain, dyn,
                                              step)
        if self.axial_struts:
            laws['axial_gain'] = strut_axial_damper(list(self.axial_struts), self.axial_gain,
                                                    dyn, step)
        if self.tcp_directions:
            laws['tcp_gain'] = tcp_damper(list(self.tcp_directions), self.tcp_gain, dyn, step)
        return laws

    def loop_laws(self, dt: float | None = None) -> list[ViscousDamper]:
        """Every damper of the node (:meth:`laws`), for offline analyses of a scenario."""
        return list(self.laws(dt=dt).values())


@dataclass(frozen=True)
class PmaParams(Sampled, SourceParams):
    """Ideal proof-mass actuator on the working platform (damping b = m_a g)."""

    directions: tuple[str, ...] = param(('x',), 'actuated axes (x, y, z)')
    proof_mass: float = param(5.0, 'proof mass m_a', 'kg', bounds=(1e-6, 1e6))
    gain: float = param(4000.0, 'velocity gain g; damping b = m_a g [N s/m]', '1/s',
                        bounds=(0.0, 1e9))
    highpass_hz: float = param(0.0, 'corner of a 2nd-order Butterworth high-pass on the '
                               'velocity; 0 = none', 'Hz', bounds=(0.0, 1e5))
    stroke_limit: float = param(0.0, 'max |stroke| of the proof mass; 0 = unlimited', 'm',
                                bounds=(0.0, 10.0))
    force_limit: float = param(0.0, 'max |force| commanded; 0 = unlimited', 'N',
                               bounds=(0.0, 1e9))

    def law(self, dt: float | None = None) -> ProofMassActuator:
        """The proof-mass actuator, integrating its proof mass with ``dt`` (default :attr:`dt`)."""
        return ProofMassActuator(list(self.directions), self.proof_mass, self.gain,
                                 self.dt if dt is None else dt,
                                 highpass_hz=self.highpass_hz, stroke_limit=self.stroke_limit,
                                 force_limit=self.force_limit)

    def loop_laws(self, dt: float | None = None) -> list[ProofMassActuator]:
        """The proof-mass actuator (:meth:`law`), for offline analyses of a scenario."""
        return [self.law(dt)]


@dataclass(frozen=True)
class ExampleControllerParams(NodeParams):
    """Template of a controller: a TCP damper in x, u = -gain * v_x."""

    gain: float = param(1000.0, 'damping of the TCP in x', 'N s/m', bounds=(0.0, MAX_GAIN))
    source_name: str = param('example', 'answers on /pentapod/forces/<source_name>')

    def loop_laws(self, dt: float | None = None) -> list[ViscousDamper]:
        """The node's law u = -gain * v_x, for offline analyses of a scenario."""
        return [tcp_damper(['x'], self.gain)]


def damper_laws(params: Mapping[str, Any] | DamperParams, source: str = '',
                dt: float | None = None) -> dict[str, ViscousDamper]:
    """
    The viscous dampers of one damper node's parameters (:meth:`DamperParams.laws`).

    ``params`` may be a section of a scenario file (checked, ConfigError naming ``source``);
    ``dt`` [s], if given, replaces the one of its ``sample_rate``.
    """
    return _typed(DamperParams, params, source).laws(source, dt)


def pma_law(params: Mapping[str, Any] | PmaParams, dt: float | None = None,
            source: str = '') -> ProofMassActuator:
    """The proof-mass actuator of one PMA node's parameters (:meth:`PmaParams.law`)."""
    return _typed(PmaParams, params, source).law(dt)


def _typed(cls: type, params: Any, source: str) -> Any:
    """Typed parameters from a section of a scenario file (or as given)."""
    return params if isinstance(params, cls) else cls.build(params, source or 'parameters')
