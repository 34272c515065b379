"""
The buildable-damper table's row for a judged controller that publishes its linear model.

The table of docs/dampers.md ("which damper to build", :mod:`pentapod_damper.design.table`)
measures every law alike; here it measures the judged controller with the same code, as one
fixed row: the controller's published discrete model at the judge's sample rate, on the
position's plant and check model. The row gives the exact TCP peak and band-RMS reduction of
the sampled loop against the machine without it, the static TCP compliance ratio, the
check-model margin (1 - spectral radius) as published and with one more sample of delay, the
largest actuator force RMS and stroke RMS per newton of TCP force.

What it leaves out: the stiffness corners (the judge runs at the pose's nominal model) and the
feed drives' own loops (the locked machine, as the study's); a black-box controller (no model)
gets no row: its FRF is only known on the identification run's bins.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Sequence

import numpy as np

from pentapod_damper.design.rows import fixed_family, RowSpec
from pentapod_damper.design.table import damper_table, DamperRow
from pentapod_damper.judge.models import PositionModel
from pentapod_sim.plant.drives import load_drives
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.design_models import DesignModel
from pentapod_sim.sim.law_families import StrutStiffness
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.tuning import TuneSettings


class _Published:
    """A published model as a law of the design code (``discrete_model`` at its own rate)."""

    def __init__(self, model: DiscreteController) -> None:
        self.model = model

    def discrete_model(self) -> DiscreteController:
        return self.model


def design_model(pos: PositionModel) -> DesignModel:
    """The position's models for the design code: no corners; strut stiffnesses unused."""
    unused = np.full((5, 2), np.nan)    # a fixed row tunes nothing: no reference stiffness
    return DesignModel(pos.name, pos.plant, pos.check, {}, load_drives(),
                       StrutStiffness(unused, unused, {}))


def buildable_row(pos: PositionModel, models: Sequence[DiscreteController], sample_rate: float,
                  direction: str, band: Sequence[float], label: str) -> DamperRow:
    """
    The design table's row of the published ``models`` (see the module docstring).

    ``models``: as published in the runs, so sampled at ``sample_rate``.
    """
    laws = [_Published(m) for m in models]

    def make(struts: Sequence[int], dt: float) -> list[Any]:
        return laws
    sensors = ', '.join(dict.fromkeys(p for m in models for p in m.sensor_ports))
    actuators = ', '.join(dict.fromkeys(p for m in models for p in m.actuator_ports))
    spec = RowSpec(label, 'fixed', fixed_family(label, sensors, actuators, make), False)
    settings = TuneSettings(sample_rate=sample_rate, direction=direction,
                            band=(float(band[0]), float(band[1])),
                            dynamics=Dynamics(delay_steps=0), extra_delay=1)
    return damper_table(design_model(pos), settings, [spec]).row(label)


def buildable_rows(pos: PositionModel, models: Sequence[DiscreteController], sample_rate: float,
                   directions: Sequence[str], band: Sequence[float], label: str
                   ) -> dict[str, DamperRow]:
    """:func:`buildable_row` per TCP direction; the check-model margins computed once."""
    out: dict[str, DamperRow] = {}
    for d in directions:
        here = pos if not out else replace(pos, check=None)   # margins: direction-independent
        row = buildable_row(here, models, sample_rate, d, band, label)
        if out:
            first = next(iter(out.values()))
            row = replace(row, check_margin=first.check_margin,
                          check_margin_extra=first.check_margin_extra)
        out[d] = row
    return out
