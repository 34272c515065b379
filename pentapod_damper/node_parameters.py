"""
Parameters of the damper, PMA and example-controller nodes, and the laws they configure.

The one home of the laws' defaults, ranges and construction: the nodes
(:mod:`pentapod_damper.nodes`) declare their parameters from these tables and build their laws
with :func:`damper_laws` and :func:`pma_law`; the offline equivalents of a scenario
(:mod:`pentapod_damper.scenario_laws`, the study) call the same functions with the scenario
file's sections. ROS-free.
"""
from __future__ import annotations

from typing import Any, Mapping

from pentapod_damper.laws import (
    band_pass_velocity,
    chord_damper,
    Dynamics,
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
from pentapod_sim.nodes.parameter_tables import SAMPLE_RATE, SOURCE_PARAMS
from pentapod_sim.parameters import Param, ParameterTable, Values

#: Upper bound of the damper gains.
MAX_GAIN = 1.0e9

#: Parameters of the actuator/sensor dynamics of a law (:class:`pentapod_damper.laws.Dynamics`).
DYNAMICS_PARAMS = (
    Param('filter_order', 'int', 0, 'low-pass between velocity sensor and actuator force: 0 = '
          'none, 1 = first order, 2 = second order', '', 0, 2),
    Param('bandwidth_hz', 'float', 0.0, 'corner frequency of the low-pass (below Nyquist)',
          'Hz', 0.0, 1.0e6),
    Param('filter_damping', 'float', 0.7071067811865476, 'damping ratio of the second-order '
          'low-pass', '', 1.0e-3, 10.0),
    Param('filter_hold', 'str', 'foh', "input assumption of the filter's exact discretisation: "
          'foh = sensor signal linear between samples, zoh = held over each step (one more '
          'sample of lag)', choices=('foh', 'zoh')),
    Param('delay_steps', 'int', 0, 'pure delay of the force in samples: 0 = sampled feedback '
          'with zero-order hold (u_k answers y_k), 1 = one-sample computational delay',
          'samples', 0, 1000),
)

_PORT_KINDS = ('bending', 'chord')
#: Parameters of the active strut laws (docs/dampers.md); ``*_gain`` may change while running.
ACTIVE_PARAMS = (
    Param('iff_struts', 'integer[]', [], 'struts (1..5) with integral force feedback from the '
          'load cell between nut and gimbal (strut<i>_force) to a force actuator in series with '
          'the nut (strut<i>_drive_force); [] or [0] = none'),
    Param('iff_gain', 'float', 100.0, 'IFF gain g of u = -g / (s + omega_i) F', '1/s', 0.0,
          MAX_GAIN, read_only=False),
    Param('iff_omega', 'float', 10.0, 'IFF corner omega_i (0: pure integrator)', 'rad/s', 0.0,
          1.0e6),
    Param('lag_struts', 'integer[]', [], 'struts (1..5) with lag displacement feedback '
          'u = +K w_c / (s + w_c) y on both axes of their lag_port ports; [] or [0] = none'),
    Param('lag_port', 'str', 'bending', 'bending (end-rotation difference, moment pair) or chord '
          '(chord deflection, chord force)', choices=_PORT_KINDS),
    Param('lag_stiffness', 'double[]', [], 'K per port (strut by strut, axes 2 then 3) or one for '
          'all [N m/rad for bending, N/m for chord]; keep it well below the port stiffness'),
    Param('lag_gain', 'float', 1.0, 'scale of every lag_stiffness', '', 0.0, 10.0,
          read_only=False),
    Param('lag_corner_hz', 'float', 50.0, 'corner w_c / 2 pi of the lag', 'Hz', 1.0e-3, 1.0e5),
    Param('bandpass_struts', 'integer[]', [], 'struts (1..5) with relative velocity feedback '
          'through a first-order band-pass on both axes of their bandpass_port ports'),
    Param('bandpass_port', 'str', 'bending', 'bending or chord', choices=_PORT_KINDS),
    Param('bandpass_gain', 'float', 50.0, 'damping b of the band-pass law [N m s/rad for '
          'bending, N s/m for chord]', '', 0.0, MAX_GAIN, read_only=False),
    Param('bandpass_highpass_hz', 'float', 5.0, 'high-pass corner', 'Hz', 1.0e-3, 1.0e5),
    Param('bandpass_lowpass_hz', 'float', 100.0, 'low-pass corner (above the high-pass one)',
          'Hz', 1.0e-3, 1.0e5),
    Param('ppf_struts', 'integer[]', [], 'struts (1..5) with positive position feedback on '
          'both axes of their ppf_port ports'),
    Param('ppf_port', 'str', 'bending', 'bending or chord', choices=_PORT_KINDS),
    Param('ppf_stiffness', 'double[]', [], 'g per port (strut by strut, axes 2 then 3) or one '
          'for all [N m/rad or N/m]; g G(0) < 1 on each port'),
    Param('ppf_gain', 'float', 1.0, 'scale of every ppf_stiffness', '', 0.0, 10.0,
          read_only=False),
    Param('ppf_frequency_hz', 'float', 27.0, 'filter frequency w_f / 2 pi (near the mode)', 'Hz',
          1.0e-3, 1.0e5),
    Param('ppf_damping', 'float', 0.3, 'filter damping ratio zeta_f', '', 1.0e-3, 10.0),
)

DAMPER = ParameterTable('damper', [
    SAMPLE_RATE,
    Param('bending_struts', 'integer[]', [], 'struts (1..5) with rotational bending dampers on '
          'both cardan axes (end-rotation difference); [] or [0] = none'),
    Param('bending_gain', 'float', 1000.0, 'bending damping b of each strut and cardan axis',
          'N m s/rad', 0.0, MAX_GAIN, read_only=False),
    Param('chord_struts', 'integer[]', [], 'struts (1..5) with translational chord dampers '
          'along e2 and e3 at the chord point (config/reduction.yaml chord_position, default '
          'mid-span) against the chord between the joints; [] or [0] = none'),
    Param('chord_gain', 'float', 20000.0, 'chord damping b of each strut and direction',
          'N s/m', 0.0, MAX_GAIN, read_only=False),
    Param('axial_struts', 'integer[]', [], 'struts (1..5) with axial dampers between strut and '
          'BP ring'),
    Param('axial_gain', 'float', 50000.0, 'axial damping b', 'N s/m', 0.0, MAX_GAIN,
          read_only=False),
    Param('tcp_directions', 'string[]', [], 'directions (x, y, z) of dampers from the TCP to '
          'ground'),
    Param('tcp_gain', 'float', 20000.0, 'TCP damping b', 'N s/m', 0.0, MAX_GAIN,
          read_only=False),
    *ACTIVE_PARAMS,
    *DYNAMICS_PARAMS,
    *SOURCE_PARAMS,
], summary='viscous velocity feedback u = -b * rate on struts and the TCP, and the active strut '
           'laws of docs/dampers.md (IFF, lag displacement, band-pass velocity, PPF), optionally '
           'through a low-pass and a delay (the same for every law of the node); the gains may '
           'be changed while running.')

PMA = ParameterTable('pma', [
    SAMPLE_RATE,
    Param('directions', 'string[]', ['x'], 'actuated axes (x, y, z)'),
    Param('proof_mass', 'float', 5.0, 'proof mass m_a', 'kg', 1e-6, 1e6),
    Param('gain', 'float', 4000.0, 'velocity gain g; damping b = m_a g [N s/m]', '1/s',
          0.0, 1e9),
    Param('highpass_hz', 'float', 0.0, 'corner of a 2nd-order Butterworth high-pass on the '
          'velocity; 0 = none', 'Hz', 0.0, 1e5),
    Param('stroke_limit', 'float', 0.0, 'max |stroke| of the proof mass; 0 = unlimited', 'm',
          0.0, 10.0),
    Param('force_limit', 'float', 0.0, 'max |force| commanded; 0 = unlimited', 'N', 0.0, 1e9),
    *SOURCE_PARAMS,
], summary='ideal proof-mass actuator on the working platform (damping b = m_a g).')

EXAMPLE_CONTROLLER = ParameterTable('example_controller', [
    Param('gain', 'float', 1000.0, 'damping of the TCP in x', 'N s/m', 0.0, MAX_GAIN),
    Param('source_name', 'str', 'example', 'answers on /pentapod/forces/<source_name>'),
], summary='template of a controller: a TCP damper in x, u = -gain * v_x.')


def _values(table: ParameterTable, params: Mapping[str, Any] | Values, source: str) -> Values:
    return params if isinstance(params, Values) else table.values(params, source)


def dynamics(params: Mapping[str, Any] | Values, source: str = '') -> Dynamics:
    """The actuator/sensor dynamics of a damper node's parameters (:data:`DYNAMICS_PARAMS`)."""
    v = _values(DAMPER, params, source)
    try:
        return Dynamics(v.filter_order, v.bandwidth_hz, v.filter_damping, v.delay_steps,
                        v.filter_hold)
    except ConfigError as err:
        raise ConfigError(f'{source}: {err}' if source else str(err)) from None


def damper_laws(params: Mapping[str, Any] | Values, source: str = '',
                dt: float | None = None) -> dict[str, ViscousDamper | SteppedLaw]:
    """
    The laws of one damper node, keyed by the name of their gain parameter.

    Parameters
    ----------
    params : mapping or Values
        The node's parameters (missing ones take the table's defaults); a mapping is checked
        against :data:`DAMPER` (ConfigError naming ``source``).
    source : str
        Where a mapping comes from, for error messages.
    dt : float, optional
        Sample time [s] of the laws' dynamics; default ``1 / sample_rate``.

    Returns
    -------
    dict
        ``bending_gain``, ``chord_gain``, ``axial_gain``, ``tcp_gain``, ``iff_gain``,
        ``lag_gain``, ``bandpass_gain``, ``ppf_gain`` -> law, for the laws configured, in this
        order (the order of the node's actuator ports). Two laws on one port add up.
    """
    v = _values(DAMPER, params, source)
    dyn = dynamics(v, source)
    dt = 1.0 / v.sample_rate if dt is None else dt
    laws: dict[str, ViscousDamper | SteppedLaw] = {}
    if v.bending_struts and v.bending_struts != [0]:
        laws['bending_gain'] = strut_bending_damper(v.bending_struts, v.bending_gain, dyn, dt)
    if v.chord_struts and v.chord_struts != [0]:
        laws['chord_gain'] = chord_damper(v.chord_struts, v.chord_gain, dyn, dt)
    if v.axial_struts and v.axial_struts != [0]:
        laws['axial_gain'] = strut_axial_damper(v.axial_struts, v.axial_gain, dyn, dt)
    if v.tcp_directions:
        laws['tcp_gain'] = tcp_damper(v.tcp_directions, v.tcp_gain, dyn, dt)
    laws.update(_active_laws(v, dyn, dt, source))
    return laws


def _chosen(struts: list[int]) -> bool:
    return bool(struts) and struts != [0]


def _per_port(values: list[float], struts: list[int], name: str, source: str) -> list[float]:
    """One value per port (2 per strut) from a list of that length or of one value."""
    values = [v for v in values if v != 0.0] if values == [0.0] else list(values)
    if len(values) == 1:
        return values * (2 * len(struts))
    if len(values) != 2 * len(struts):
        where = f'{source}: ' if source else ''
        raise ConfigError(f'{where}{name} has {len(values)} values; give one, or one per port '
                          f'({2 * len(struts)} for struts {struts})')
    return values


def _active_laws(v: Values, dyn: Dynamics, dt: float, source: str) -> dict[str, SteppedLaw]:
    """The active strut laws of a damper node, keyed by the name of their gain parameter."""
    laws: dict[str, SteppedLaw] = {}
    try:
        if _chosen(v.iff_struts):
            laws['iff_gain'] = integral_force_feedback(v.iff_struts, v.iff_gain, v.iff_omega,
                                                       dt, dyn)
        if _chosen(v.lag_struts):
            laws['lag_gain'] = lag_displacement_feedback(
                v.lag_port, v.lag_struts, _per_port(v.lag_stiffness, v.lag_struts,
                                                    'lag_stiffness', source),
                v.lag_corner_hz, dt, dyn)
            laws['lag_gain'].set_gain(v.lag_gain)
        if _chosen(v.bandpass_struts):
            laws['bandpass_gain'] = band_pass_velocity(
                v.bandpass_port, v.bandpass_struts, v.bandpass_gain, v.bandpass_highpass_hz,
                v.bandpass_lowpass_hz, dt, dyn)
        if _chosen(v.ppf_struts):
            laws['ppf_gain'] = positive_position_feedback(
                v.ppf_port, v.ppf_struts, _per_port(v.ppf_stiffness, v.ppf_struts,
                                                    'ppf_stiffness', source),
                v.ppf_frequency_hz, v.ppf_damping, dt, dyn)
            laws['ppf_gain'].set_gain(v.ppf_gain)
    except ConfigError as err:
        raise ConfigError(f'{source}: {err}' if source and source not in str(err)
                          else str(err)) from None
    return laws


def pma_law(params: Mapping[str, Any] | Values, dt: float,
            source: str = '') -> ProofMassActuator:
    """
    The proof-mass actuator of one PMA node, integrating its proof mass with ``dt`` [s].

    Parameters as in :func:`damper_laws`, checked against :data:`PMA`.
    """
    v = _values(PMA, params, source)
    return ProofMassActuator(v.directions, v.proof_mass, v.gain, dt,
                             highpass_hz=v.highpass_hz, stroke_limit=v.stroke_limit,
                             force_limit=v.force_limit)
