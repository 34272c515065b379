"""
Families of strut damping laws with their tunable parameters, for :mod:`pentapod_sim.sim.tuning`.

A family turns a parameter vector into the laws of one design (objects with ``discrete(dt)``
and ``continuous()`` returning :class:`~pentapod_sim.sim.controllers.DiscreteController`) on a
set of struts, and says which machine it runs on: ``locked`` (the FE model: drives infinitely
stiff, as the study) or ``drives`` (:class:`~pentapod_sim.plant.drives.DrivenPlant` with the
feed drives' cascades). Gains that scale with the strut are given as fractions of a reference
stiffness (:class:`StrutStiffness`): the lag law's K of the strut's bending stiffness ``E I /
L`` (bending ports) or its lateral stiffness ``3 E I L / (a^2 b^2)`` at the chord point
(chord ports), the PPF gain of the port's own static stiffness ``1 / G(0)``.

Units: as the laws' (:mod:`pentapod_sim.sim.law_models`); frequencies in Hz.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.drives import DriveParams
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.drives import FeedDrives
from pentapod_sim.sim.law_models import band_pass, Dynamics, iff, lag_displacement, ppf

MACHINES = ('locked', 'drives')
#: A family's builder: (values, struts, context) -> laws, each with ``discrete(dt)`` and
#: ``continuous()`` returning a DiscreteController or a list of them.
Builder = Callable[[Mapping[str, float], Sequence[int], Mapping[str, Any]], list[Any]]
Values = Mapping[str, float]
Context = Mapping[str, Any]


@dataclass(frozen=True)
class Parameter:
    """One tunable parameter: name, unit, search bounds, searched on a log scale or not."""

    name: str
    unit: str
    lower: float
    upper: float
    log: bool = True

    def grid(self, n: int) -> np.ndarray:
        """``n`` values spanning the bounds."""
        return (np.geomspace(self.lower, self.upper, n) if self.log
                else np.linspace(self.lower, self.upper, n))


@dataclass(frozen=True)
class StrutStiffness:
    """
    Reference stiffnesses of the strut ports at one position.

    ``bending[i, k]``: E I_k / L_i [N m/rad] of strut i+1 about e_{k+2}; ``chord[i, k]``:
    3 E I_k L_i / (a^2 b^2) [N/m] at the chord point (a = s L_i, b = (1 - s) L_i);
    ``port_static``: collocated static compliance 1 / stiffness of named ports (from the
    plant), for the PPF gain.
    """

    bending: np.ndarray
    chord: np.ndarray
    port_static: Mapping[str, float]

    def of(self, port: str) -> float:
        """Reference stiffness of an actuator port (bending moment or chord force)."""
        strut, k = int(port[5]) - 1, int(port[-1]) - 2
        if '_bending_moment_' in port:
            return float(self.bending[strut, k])
        if '_chord_force_' in port:
            return float(self.chord[strut, k])
        raise ConfigError(f'no reference stiffness for port {port!r}')


@dataclass(frozen=True)
class Family:
    """
    A law family: name, what it needs, its parameters and its builder.

    ``build(values, struts, context)`` returns the laws; ``context`` holds the position's
    :class:`StrutStiffness`, the drives' parameters, the target mode frequency [Hz] and the
    actuator/sensor dynamics.
    """

    name: str
    machine: str
    sensors: str
    actuators: str
    parameters: tuple[Parameter, ...]
    build: Builder

    def laws(self, values: Mapping[str, float], struts: Sequence[int],
             context: Mapping[str, Any]) -> list[Any]:
        """The laws of one design (ConfigError names a missing parameter)."""
        missing = [p.name for p in self.parameters if p.name not in values]
        if missing:
            raise ConfigError(f'family {self.name!r} needs {", ".join(missing)}')
        return self.build(values, struts, context)


def _ports(struts: Sequence[int], kind: str) -> list[str]:
    return [f'strut{i}_{kind}_{k}' for i in struts for k in (2, 3)]


def _low_passed(values: Mapping[str, float], dynamics: Dynamics) -> Dynamics:
    """The context's delay with the second-order low-pass of ``lowpass_hz`` on the sensor."""
    return Dynamics(2, values['lowpass_hz'], 0.7071067811865476, dynamics.delay_steps,
                    dynamics.hold)


def _iff(values: Values, struts: Sequence[int], context: Context) -> list[Any]:
    g = values['gain']
    return [iff([f'strut{i}_force' for i in struts], [f'strut{i}_drive_force' for i in struts],
                g, values['omega_ratio'] * g, _low_passed(values, context['dynamics']))]


def _hac_lac(values: Values, struts: Sequence[int], context: Context) -> list[Any]:
    """The drives of every strut, IFF inside the loops of ``struts``.

    The IFF command is computed in the drive's own cycle (it then shares the drive's delay);
    the tuner's extra delay delays it once more.
    """
    g = values['gain']
    params: DriveParams = context['drives']
    extra = Dynamics(delay_steps=int(context.get('extra', 0)))
    return [FeedDrives(params, tuple(range(1, 6)), 0.0)] if not g else [
        _DrivesWithIff(params, tuple(struts), g, values['omega_ratio'] * g,
                       _low_passed(values, extra))]


@dataclass(frozen=True)
class _DrivesWithIff:
    """Drives of all struts; IFF inside the loops of ``struts`` only."""

    params: DriveParams
    struts: tuple[int, ...]
    gain: float
    omega: float
    dynamics: Dynamics

    def _parts(self) -> list[FeedDrives]:
        rest = tuple(i for i in range(1, 6) if i not in self.struts)
        parts = [FeedDrives(self.params, self.struts, self.gain, self.omega, self.dynamics)]
        return parts + ([FeedDrives(self.params, rest)] if rest else [])

    def discrete(self, dt: float) -> list[DiscreteController]:
        """Controllers of both groups (a list)."""
        return [p.discrete(dt) for p in self._parts()]

    def continuous(self) -> list[DiscreteController]:
        """Continuous controllers of both groups (a list)."""
        return [p.continuous() for p in self._parts()]


def _band_pass(values: Values, struts: Sequence[int], context: Context) -> list[Any]:
    ports = _ports(struts, 'bending_moment')
    return [band_pass([collocated_output(p) for p in ports], ports, values['gain'],
                      values['highpass_hz'], values['lowpass_hz'], context['dynamics'])]


def _lag(kind: str) -> Builder:
    def build(values: Values, struts: Sequence[int], context: Context) -> list[Any]:
        ports = _ports(struts, kind)
        stiff: StrutStiffness = context['stiffness']
        k = [values['stiffness_ratio'] * stiff.of(p) for p in ports]
        return [lag_displacement([collocated_output(p, 'displacement') for p in ports], ports,
                                 k, values['corner_hz'], context['dynamics'])]
    return build


def _ppf(values: Values, struts: Sequence[int], context: Context) -> list[Any]:
    ports = _ports(struts, 'bending_moment')
    sensors = [collocated_output(p, 'displacement') for p in ports]
    stiff: StrutStiffness = context['stiffness']
    gains = [values['gain_ratio'] / stiff.port_static[s] for s in sensors]
    return [ppf(sensors, ports, gains, values['frequency_ratio'] * context['target_hz'],
                values['damping'], context['dynamics'])]


_OMEGA = Parameter('omega_ratio', '-', 0.01, 30.0)
#: Second-order low-pass of the load cell: it must take the strut's own axial mode on its
#: drive link (710-750 Hz, lightly damped, strong in the collocated force) out of the loop.
_LOWPASS = Parameter('lowpass_hz', 'Hz', 40.0, 600.0)
FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family('iff', 'locked', 'load cell between nut and gimbal',
           'force actuator in series with the nut (piezo stack)',
           (Parameter('gain', '1/s', 10.0, 1.0e4), _OMEGA, _LOWPASS), _iff),
    Family('hac-lac', 'drives', 'load cell between nut and gimbal, motor encoder',
           'the feed drive (IFF into its force command)',
           (Parameter('gain', '1/s', 10.0, 1.0e4), _OMEGA, _LOWPASS), _hac_lac),
    Family('band-pass', 'locked', 'strut end-rotation rates (both cardan axes)',
           'moment pair at the strut ends', (
               Parameter('gain', 'N m s/rad', 1.0, 3.0e3),
               Parameter('highpass_hz', 'Hz', 2.0, 25.0),
               Parameter('lowpass_hz', 'Hz', 50.0, 1000.0)), _band_pass),
    Family('lag-bending', 'locked', 'strut end-rotation difference (both cardan axes)',
           'moment pair at the strut ends', (
               Parameter('stiffness_ratio', '-', 0.02, 1.0),
               Parameter('corner_hz', 'Hz', 3.0, 300.0)), _lag('bending_moment')),
    Family('lag-chord', 'locked', 'chord-point deflection of the strut (e2, e3)',
           'lateral force at the chord point, reacted at the joints', (
               Parameter('stiffness_ratio', '-', 0.02, 1.0),
               Parameter('corner_hz', 'Hz', 3.0, 300.0)), _lag('chord_force')),
    Family('ppf', 'locked', 'strut end-rotation difference (both cardan axes)',
           'moment pair at the strut ends', (
               Parameter('gain_ratio', '-', 0.02, 0.95),
               Parameter('frequency_ratio', '-', 0.7, 1.4, log=False),
               Parameter('damping', '-', 0.03, 0.7)), _ppf),
)}


def family(name: str) -> Family:
    """The family called ``name`` (ConfigError lists the known ones)."""
    try:
        return FAMILIES[name]
    except KeyError:
        raise ConfigError(f'unknown law family {name!r}; known: {", ".join(FAMILIES)}') \
            from None
