"""
The verdict's laws checked on the full check model.

The tuner checks every design on a check model it can afford (:func:`pentapod_sim.sim.
design_models.load_design_model`'s ``check_subset_hz``: the check modes below a frequency,
with the static correction of the others); the laws the verdict names (the best strut-only
law, and the best one without the feed drives' loops) are then checked on every mode of the
full check model, with the law's delay and with one more sample. A law that fails there loses
its place and the next best is checked. :func:`shipped_judge` judges a scenario file written
from the table (absolute gains of the position it was tuned at) at another position with the
tuner's constraints (docs/dampers.md, "The shipped scenario files at P2"). ROS-free.
"""
from __future__ import annotations

from dataclasses import replace
import logging
from typing import Callable, Sequence

import numpy as np

from pentapod_damper.design.report import best_strut_law, Record, records
from pentapod_damper.design.rows import default_rows
from pentapod_damper.design.scenarios import gains_of
from pentapod_damper.design.table import (
    DamperTable,
    magnitude,
    measure_row,
    stroke,
    with_lowband,
)
from pentapod_sim.sim.design_models import DesignModel
from pentapod_sim.sim.law_families import StrutStiffness
from pentapod_sim.sim.law_models import Dynamics
from pentapod_sim.sim.tuning import Evaluation, Judge, TuneSettings

LOG = logging.getLogger(__name__)


def verify_best(table: DamperTable, model: DesignModel, attempts: int = 3,
                progress: Callable[[str], None] | None = None) -> DamperTable:
    """
    ``table`` with the full check model's margins of the laws its verdict names.

    Checks the best strut-only law, the best without the drives and the best that keeps the
    low-band compliance (:func:`~pentapod_damper.design.report.best_strut_law`) until they
    pass on ``model.full_check`` or ``attempts`` laws per kind have failed (a failed row keeps
    its negative margins, so the verdict passes it over).
    """
    say = progress or (lambda msg: LOG.info('%s', msg))
    full = model.full_check
    if full is None:
        return table
    checked = replace(model, check=full, driven={})
    specs = {spec.name: spec for spec in default_rows()}
    table = replace(table, full_check_modes=full.n_modes,
                    full_check_f_max_hz=float(full.meta.get('check_f_max_hz', np.nan)))
    for drives, low_band in ((True, False), (False, False), (True, True)):
        for _ in range(attempts):
            best = best_strut_law(records(table), drives=drives, low_band=low_band)
            if best is None:
                break
            index = next(i for i, r in enumerate(table.rows) if r.law == best['law'])
            row = table.rows[index]
            if np.isfinite(row.full_check_margin):
                break                                    # verified and passed
            judge = Judge(checked, specs[row.law].family, replace(table.settings,
                                                                  refine_iterations=0))
            radii = judge.check(dict(row.gains))
            say(f'{table.position}: {row.law}: full check model ({full.n_modes} modes) radius '
                f'{radii[0]:.6f} / {radii[1]:.6f} (extra delay)')
            rows = list(table.rows)
            rows[index] = replace(row, full_check_margin=1.0 - radii[0],
                                  full_check_margin_extra=1.0 - radii[1])
            table = replace(table, rows=tuple(rows))
            if radii[0] < 1.0 and radii[1] < 1.0:
                break
    return table


def remeasure(table: DamperTable, model: DesignModel, laws: Sequence[str],
              progress: Callable[[str], None] | None = None) -> DamperTable:
    """
    ``table`` with the rows of ``laws`` measured again at their tuned gains (no tuning).

    Peak, RMS, statics, effort, struts 1+2 shares, stroke and the figure's FRF (so the
    low-band ratio) come from the code as it is now, on ``model``'s design plant; the check
    margins, full-check margins and the tuner's feasibility verdict are kept (they need the
    check model and the corners). For rows measured with an earlier version of the loop FRF
    (the drives' rows before ``loop_frf.modal_form`` balanced its matrix).
    """
    say = progress or (lambda msg: LOG.info('%s', msg))
    specs = {spec.name: spec for spec in default_rows()}
    settings = replace(table.settings, refine_iterations=0)
    base = Evaluation({}, peak=table.baseline_peak, rms=table.baseline_rms)
    rows, magnitudes = list(table.rows), dict(table.magnitudes)
    for index, row in enumerate(rows):
        if row.law not in laws:
            continue
        spec, values = specs[row.law], dict(row.gains)
        judge = Judge(replace(model, check=None), spec.family, settings)
        best = judge.evaluate(values, robust=False)
        new = measure_row(spec, judge, values, best, base, None, say)
        magnitudes[row.law] = magnitude(judge, values, spec.kind == 'ideal')
        value, unit = stroke(judge, values)
        rows[index] = replace(row, peak_reduction=new.peak_reduction,
                              rms_reduction=new.rms_reduction, peak_hz=new.peak_hz,
                              static_ratio=new.static_ratio,
                              effort_rms_per_n=new.effort_rms_per_n,
                              share12_peak=new.share12_peak, share12_rms=new.share12_rms,
                              stroke_rms_per_n=value, stroke_unit=unit)
    return with_lowband(replace(table, rows=tuple(rows), magnitudes=magnitudes))


def shipped_judge(record: Record, model: DesignModel, tuned: StrutStiffness
                  ) -> tuple[Judge, dict[str, float]]:
    """
    The tuner's judge, on ``model``'s position, of a scenario file written from ``record``.

    A scenario file holds absolute gains (:func:`pentapod_damper.design.scenarios.node_params`:
    the lag and PPF stiffnesses are the tuned fractions of the reference stiffnesses of the
    position the record was tuned at, ``tuned``; PPF's frequency is the fraction of that
    position's peak frequency), so at another position it runs the record's values against
    ``tuned``'s references, not against ``model``'s: the judge gets ``tuned`` and the record's
    target frequency, and its limits are the table's (sample rate, delay and band of the
    record, the tuner's default static and force limits). Returns the judge and the record's
    values; ``judge.evaluate(values)`` gives the verdict under ``model``'s constraints (its
    corners, one more sample of delay), ``judge.check(values)`` the check-model radii.
    """
    spec = {s.name: s for s in default_rows()}[record['law']]
    low, high = (float(f) for f in record['band_hz'].split('-'))
    settings = TuneSettings(sample_rate=float(record['sample_rate_hz']),
                            direction=record['direction'], band=(low, high),
                            dynamics=Dynamics(delay_steps=int(record['delay_steps'])),
                            refine_iterations=0)
    judge = Judge(replace(model, stiffness=tuned, driven={}), spec.family, settings,
                  target_hz=float(record['baseline_peak_hz']))
    return judge, gains_of(record)
