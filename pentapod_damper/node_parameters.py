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
    band_pass_velocity,
    chord_damper,
    Dynamics,
    feed_drives,
    integral_force_feedback,
    lag_displacement_feedback,
    positive_position_feedback,
    ProofMassActuator,
    SteppedLaw,
    strut_axial_damper,
    strut_bending_damper,
    tcp_damper,
    ViscousDamper,
)
from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import NodeParams, param, Sampled, SourceParams
from pentapod_sim.plant.drives import drives_path, load_drives

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


_PORT_KINDS = ('bending', 'chord')


@dataclass(frozen=True)
class ActiveLawParams(NodeParams):
    """
    The active strut laws of docs/dampers.md: IFF, lag displacement, band-pass velocity, PPF.

    Each law runs on the struts its ``*_struts`` list names (none by default); its ``*_gain``
    may be changed while running.
    """

    iff_struts: tuple[int, ...] = param((), 'struts (1..5) with integral force feedback from the '
                                        'load cell between nut and gimbal (strut<i>_force) to a '
                                        'force actuator in series with the nut '
                                        '(strut<i>_drive_force); [] or [0] = none')
    iff_gain: float = param(100.0, 'IFF gain g of u = -g / (s + omega_i) F', '1/s',
                            bounds=(0.0, MAX_GAIN), read_only=False)
    iff_omega: float = param(10.0, 'IFF corner omega_i (0: pure integrator)', 'rad/s',
                             bounds=(0.0, 1.0e6))
    lag_struts: tuple[int, ...] = param((), 'struts (1..5) with lag displacement feedback '
                                        'u = +K w_c / (s + w_c) y on both axes of their lag_port '
                                        'ports; [] or [0] = none')
    lag_port: str = param('bending', 'bending (end-rotation difference, moment pair) or chord '
                          '(chord deflection, chord force)', choices=_PORT_KINDS)
    lag_stiffness: tuple[float, ...] = param((), 'K per port (strut by strut, axes 2 then 3) or '
                                             'one for all [N m/rad for bending, N/m for chord]; '
                                             'keep it well below the port stiffness')
    lag_gain: float = param(1.0, 'scale of every lag_stiffness', bounds=(0.0, 10.0),
                            read_only=False)
    lag_corner_hz: float = param(50.0, 'corner w_c / 2 pi of the lag', 'Hz',
                                 bounds=(1.0e-3, 1.0e5))
    bandpass_struts: tuple[int, ...] = param((), 'struts (1..5) with relative velocity feedback '
                                             'through a first-order band-pass on both axes of '
                                             'their bandpass_port ports; [] or [0] = none')
    bandpass_port: str = param('bending', 'bending or chord', choices=_PORT_KINDS)
    bandpass_gain: float = param(50.0, 'damping b of the band-pass law [N m s/rad for bending, '
                                 'N s/m for chord]', bounds=(0.0, MAX_GAIN), read_only=False)
    bandpass_highpass_hz: float = param(5.0, 'high-pass corner', 'Hz', bounds=(1.0e-3, 1.0e5))
    bandpass_lowpass_hz: float = param(100.0, 'low-pass corner (above the high-pass one)', 'Hz',
                                       bounds=(1.0e-3, 1.0e5))
    ppf_struts: tuple[int, ...] = param((), 'struts (1..5) with positive position feedback on '
                                        'both axes of their ppf_port ports; [] or [0] = none')
    ppf_port: str = param('bending', 'bending or chord', choices=_PORT_KINDS)
    ppf_stiffness: tuple[float, ...] = param((), 'g per port (strut by strut, axes 2 then 3) or '
                                             'one for all [N m/rad or N/m]; g G(0) < 1 on each '
                                             'port')
    ppf_gain: float = param(1.0, 'scale of every ppf_stiffness', bounds=(0.0, 10.0),
                            read_only=False)
    ppf_frequency_hz: float = param(27.0, 'filter frequency w_f / 2 pi (near the mode)', 'Hz',
                                    bounds=(1.0e-3, 1.0e5))
    ppf_damping: float = param(0.3, 'filter damping ratio zeta_f', bounds=(1.0e-3, 10.0))
    drive_struts: tuple[int, ...] = param((), "struts (1..5) whose feed drives' servo cascade "
                                          'the node runs (position P and velocity PI on the '
                                          'motor encoder strut<i>_motor_position, _velocity, '
                                          "with the drives' own delay, into "
                                          'strut<i>_motor_force); needs a plant with the '
                                          "drives (its parameter drives); [] or [0] = none")
    drive_file: str = param('drives.yaml', "the drives' parameters (a bare name is looked up "
                            "in the package's config folder): the plant's drives file")
    drive_iff_gain: float = param(0.0, 'HAC-LAC: IFF gain g of w = -g / (s + omega_i) F from '
                                  'the load cell strut<i>_force into the force command, '
                                  "through the node's low-pass, its delay_steps added to the "
                                  "drives' own delay; 0 = the feed drives alone; settable "
                                  'while running between values > 0 (the cascade is rebuilt '
                                  'with it; to or from 0 is refused: it adds or drops the load '
                                  'cells)', '1/s', bounds=(0.0, MAX_GAIN), read_only=False)
    drive_iff_omega: float = param(0.0, 'HAC-LAC: IFF corner omega_i', 'rad/s',
                                   bounds=(0.0, 1.0e6))

    def active_laws(self, dyn: Dynamics, dt: float, source: str = '') -> dict[str, SteppedLaw]:
        """
        The active laws configured, keyed by the name of their gain parameter.

        ``iff_gain``, ``lag_gain``, ``bandpass_gain``, ``ppf_gain``, ``drive_iff_gain`` (the
        drives' cascade, its gain parameter the IFF gain) -> law, in this order, with
        the dynamics ``dyn`` at the sample time ``dt`` [s]. ConfigError (naming ``source``) for
        a combination the laws refuse.
        """
        laws: dict[str, SteppedLaw] = {}
        try:
            if self.iff_struts:
                laws['iff_gain'] = integral_force_feedback(list(self.iff_struts), self.iff_gain,
                                                           self.iff_omega, dt, dyn)
            if self.lag_struts:
                laws['lag_gain'] = lag_displacement_feedback(
                    self.lag_port, list(self.lag_struts),
                    _per_port(self.lag_stiffness, self.lag_struts, 'lag_stiffness'),
                    self.lag_corner_hz, dt, dyn)
                laws['lag_gain'].set_gain(self.lag_gain)
            if self.bandpass_struts:
                laws['bandpass_gain'] = band_pass_velocity(
                    self.bandpass_port, list(self.bandpass_struts), self.bandpass_gain,
                    self.bandpass_highpass_hz, self.bandpass_lowpass_hz, dt, dyn)
            if self.ppf_struts:
                laws['ppf_gain'] = positive_position_feedback(
                    self.ppf_port, list(self.ppf_struts),
                    _per_port(self.ppf_stiffness, self.ppf_struts, 'ppf_stiffness'),
                    self.ppf_frequency_hz, self.ppf_damping, dt, dyn)
                laws['ppf_gain'].set_gain(self.ppf_gain)
            if self.drive_struts:
                laws['drive_iff_gain'] = feed_drives(
                    list(self.drive_struts), load_drives(drives_path(self.drive_file)), dt,
                    self.drive_iff_gain, self.drive_iff_omega, dyn)
        except ConfigError as err:
            raise ConfigError(f'{source}: {err}' if source else str(err)) from None
        return laws


def _per_port(values: tuple[float, ...], struts: tuple[int, ...], name: str) -> list[float]:
    """One value per port (2 per strut) from a list of that length or of one value."""
    if len(values) == 1:
        return list(values) * (2 * len(struts))
    if len(values) != 2 * len(struts):
        raise ConfigError(f'{name} has {len(values)} values; give one, or one per port '
                          f'({2 * len(struts)} for struts {list(struts)})')
    return list(values)


@dataclass(frozen=True)
class DamperParams(Sampled, ActiveLawParams, DynamicsParams, SourceParams):
    """
    Viscous velocity feedback u = -b * rate on struts and the TCP, and active strut laws.

    The active strut laws are those of docs/dampers.md (IFF, lag displacement, band-pass
    velocity, PPF); every law of the node runs through the same low-pass and delay; the gains
    may be changed while running.
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

    def laws(self, source: str = '',
             dt: float | None = None) -> dict[str, ViscousDamper | SteppedLaw]:
        """
        The laws of the node, keyed by the name of their gain parameter.

        ``bending_gain``, ``chord_gain``, ``axial_gain``, ``tcp_gain``, then the active laws
        (:meth:`ActiveLawParams.active_laws`) -> law, for the laws configured, in this order
        (the order of the node's actuator ports; two laws on one port add up); their dynamics
        are discretised with ``dt`` [s] (default :attr:`dt`). ConfigError (naming ``source``)
        for dynamics or options the laws refuse.
        """
        try:
            dyn = self.dynamics()
        except ConfigError as err:
            raise ConfigError(f'{source}: {err}' if source else str(err)) from None
        step = self.dt if dt is None else dt
        laws: dict[str, ViscousDamper | SteppedLaw] = {}
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
        laws.update(self.active_laws(dyn, step, source))
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
                dt: float | None = None) -> dict[str, ViscousDamper | SteppedLaw]:
    """
    The laws of one damper node's parameters (:meth:`DamperParams.laws`).

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
