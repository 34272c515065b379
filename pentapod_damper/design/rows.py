"""
The rows of the "which damper to build" table: what each law is and how it is built.

Tuned rows are law families of :mod:`pentapod_sim.sim.law_families` (gains found by
:func:`pentapod_sim.sim.tuning.tune`); fixed rows are the laws the scenario files ship (or the
paper's ideal damper), wrapped as families without parameters so that one judge
(:class:`pentapod_sim.sim.tuning.Judge`) measures every row the same way. One more sample of
delay on a fixed law delays its efforts (:func:`pentapod_sim.sim.law_models.delay_output`).
A fixed row of a scenario whose plant steps the feed drives (its ``drives``,
:func:`pentapod_sim.scenario.laws.scenario_drives`) runs on the machine with the drives, its
drives' cascade (with its IFF) among its laws.

Units: gains as the laws'; frequencies Hz.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping, Sequence

from pentapod_damper.laws import Dynamics, ProofMassActuator, ViscousDamper
from pentapod_damper.laws.linear import DrivesLaw
from pentapod_damper.scenario_laws import scenario_laws
from pentapod_sim.errors import ConfigError
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.scenario.laws import scenario_drives
from pentapod_sim.sim.drives import FeedDrives
from pentapod_sim.sim.law_families import Family, family
from pentapod_sim.sim.law_models import delay_output


@dataclass(frozen=True)
class RowSpec:
    """
    One row: its name, the family it tunes or the fixed laws it runs, and what it needs.

    ``kind``: 'tuned' (``family`` names a law family), 'fixed' (``laws`` builds them), or
    'ideal' (the paper's continuous viscous damper, ``laws`` builds it without dynamics).
    ``strut_law``: sensors and actuators on the struts only (counts for the done-when and
    has a struts 1+2 share).
    """

    name: str
    kind: str
    family: Family
    strut_law: bool
    note: str = ''


@dataclass(frozen=True)
class _FixedModels:
    """Adapter: fixed laws as an object with ``discrete(dt)`` (a list of controllers)."""

    make: Callable[[float], list[Any]]
    extra: int

    def discrete(self, dt: float) -> list[Any]:
        out = []
        for law in self.make(dt):
            if isinstance(law, DrivesLaw):
                # the drives are the machine and keep their delay; their IFF gets the extra
                # sample, as the tuned HAC-LAC family's does
                cascade = law.law
                if cascade.iff_gain and self.extra:
                    dyn = cascade.iff_dynamics
                    cascade = replace(cascade,
                                      iff_dynamics=dyn.with_delay(dyn.delay_steps + self.extra))
                out.append(cascade.discrete(dt))
            else:
                out.append(delay_output(law.discrete_model(), self.extra))
        return out

    def continuous(self) -> list[Any]:
        return [law.continuous_model() for law in self.make(1.0)]


def fixed_family(name: str, sensors: str, actuators: str,
                 make: Callable[[Sequence[int], float], list[Any]],
                 machine: str = 'locked') -> Family:
    """A family without parameters that runs ``make(struts, dt)`` on ``machine``."""
    def build(values: Mapping[str, float], struts: Sequence[int],
              context: Mapping[str, Any]) -> list[Any]:
        return [_FixedModels(lambda dt: make(struts, dt), int(context.get('extra', 0)))]
    return Family(name, machine, sensors, actuators, (), build)


def scenario_family(name: str, scenario: str, sensors: str, actuators: str) -> Family:
    """
    A fixed row of a scenario's laws (:func:`_scenario_dampers`), on the machine it runs on.

    With the scenario's ``drives`` the row's machine is ``drives`` (the design model's
    drives on every strut, :meth:`pentapod_sim.sim.design_models.DesignModel.with_drives`):
    ConfigError if the scenario's drives are other ones (another file's parameters, or not
    on all five struts), since the table's machine has one set of drives.
    """
    drives = scenario_drives(scenario)
    make = _scenario_dampers(scenario)
    if drives is None:
        return fixed_family(name, sensors, actuators, make)

    def build(values: Mapping[str, float], struts: Sequence[int],
              context: Mapping[str, Any]) -> list[Any]:
        mine, theirs = (replace(p, source='') for p in (drives.params, context['drives']))
        if drives.struts != (1, 2, 3, 4, 5) or mine != theirs:
            raise ConfigError(f'scenario {scenario!r}: its drives ({drives.describe()}) are '
                              "not the design model's drives on all five struts "
                              f"({context['drives'].source})")
        return [_FixedModels(lambda dt: make(struts, dt), int(context.get('extra', 0)))]
    return Family(name, 'drives', sensors, actuators, (), build)


def _scenario_dampers(scenario: str) -> Callable[[Sequence[int], float], list[Any]]:
    """
    The scenario's viscous dampers on the given struts only, and its drives' cascade.

    Dampers on strut ports are kept for the given struts; the feed drives stay on all their
    struts (they are the machine), their IFF only inside the loops of the given struts.
    """
    sections = read_scenario(scenario).sections

    def make(struts: Sequence[int], dt: float) -> list[Any]:
        out: list[Any] = []
        for law in scenario_laws(sections, dt):
            if isinstance(law, DrivesLaw):
                out += _drives_on(law.law, struts, dt)
                continue
            if not isinstance(law, ViscousDamper):
                continue
            keep = [k for k, port in enumerate(law.actuator_ports)
                    if not port.startswith('strut') or int(port[5]) in struts]
            if keep:
                out.append(ViscousDamper([law.actuator_ports[k] for k in keep],
                                         [float(g) for g in law.gains[keep]], law.dynamics,
                                         dt))
        return out
    return make


def _drives_on(cascade: FeedDrives, struts: Sequence[int], dt: float) -> list[Any]:
    """A scenario's drives' cascade with its IFF only inside the loops of ``struts``."""
    inside = tuple(i for i in cascade.struts if i in struts)
    rest = tuple(i for i in cascade.struts if i not in struts)
    parts = ([replace(cascade, struts=inside)] if inside else []) + (
        [replace(cascade, struts=rest, iff_gain=0.0, iff_omega=0.0)] if rest else [])
    return [DrivesLaw(part, dt) for part in parts]


def _ideal_bending(gain: float) -> Callable[[Sequence[int], float], list[Any]]:
    def make(struts: Sequence[int], dt: float) -> list[Any]:
        return [ViscousDamper([f'strut{i}_bending_moment_{k}' for i in struts for k in (2, 3)],
                              gain, Dynamics(), dt)]
    return make


def _pma(mass: float, gain: float, highpass_hz: float) -> Callable[[Sequence[int], float],
                                                                     list[Any]]:
    def make(struts: Sequence[int], dt: float) -> list[Any]:
        return [ProofMassActuator(['x'], mass, gain, dt, highpass_hz=highpass_hz)]
    return make


#: The row of the feed drives' position loops without a law (the drives' own damping).
DRIVES_ROW = 'feed drives alone (position loops)'
#: The paper's strut bending damper as the damper node's default (N m s/rad per port).
IDEAL_BENDING_GAIN = 1000.0


def default_rows() -> tuple[RowSpec, ...]:
    """The table's rows, in the issue's order."""
    bending = 'strut end-rotation rates (both cardan axes)'
    moment = 'moment pair at the strut ends'
    return (
        RowSpec('ideal viscous bending (paper)', 'ideal', fixed_family(
            'ideal', bending, moment, _ideal_bending(IDEAL_BENDING_GAIN)), True,
            f'{IDEAL_BENDING_GAIN:g} N m s/rad, continuous, no filter or delay'),
        RowSpec('velocity feedback (buildable today)', 'fixed', scenario_family(
            'strut_damping_all', 'strut_damping_all', bending, moment),
            True, 'scenario strut_damping_all'),
        RowSpec(DRIVES_ROW, 'tuned', family('hac-lac'), True,
                'config/drives.yaml, IFF gain 0'),
        RowSpec('IFF', 'tuned', family('iff'), True),
        RowSpec('IFF + position loop (HAC-LAC)', 'tuned', family('hac-lac'), True),
        RowSpec('lag displacement, bending', 'tuned', family('lag-bending'), True),
        RowSpec('lag displacement, chord', 'tuned', family('lag-chord'), True),
        RowSpec('band-pass velocity, bending', 'tuned', family('band-pass'), True),
        RowSpec('PPF, bending', 'tuned', family('ppf'), True),
        RowSpec('PMA 5 kg, 5 Hz high-pass', 'fixed', fixed_family(
            'pma', 'mount velocity (x)', 'proof-mass actuator on the platform (x)',
            _pma(5.0, 4000.0, 5.0)), False, "scenario pma_5kg with the study's 5 Hz high-pass"),
        RowSpec('TCP damper', 'fixed', scenario_family(
            'tcp_damping', 'tcp_damping', 'TCP velocity (x, y, z)',
            'damper from the TCP to ground'), False, 'scenario tcp_damping'),
    )
