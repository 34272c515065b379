"""
The study's tables, computed from its records: one row per position, scenario or mode.

Each function returns the rows of one CSV table of the report (:mod:`.report`); the summary
and the struts-1+2 shares are typed rows (:class:`SummaryRow`, :class:`ShareRow`), which the
command line also prints. Units as the column names say (um/N, Hz, mm, N).
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from pentapod_damper.study.analytic import improvement_share, peak_and_rms
from pentapod_damper.study.pma import bounded_stroke, PmaDesign, requirement_row
from pentapod_damper.study.records import as_row, FrfRun, Row, ScenarioAnalytic, StudyResults

#: Columns of damping.csv: the analytic mode, then what its damping run identified.
DAMPING_COLUMNS = ('position', 'scenario', 'direction', 'rank', 'mode', 'fe_mode', 'cause',
                   'open_freq_hz', 'open_zeta', 'sampled_freq_hz', 'sampled_zeta',
                   'continuous_zeta', 'sampled_mac', 'measured_freq_hz', 'measured_zeta',
                   'zeta_error', 'freq_error', 'peak_analytic_um_per_N', 'peak_measured_um_per_N',
                   'peak_error_db', 'decay_time_s')


@dataclass
class SummaryRow:
    """
    One (position, scenario): exact peak, reductions, truncation check, testbed check.

    Peaks and peak reductions are exact (searched at the resonances); the RMS reduction is
    taken on the frequency grid; the stable depth gain is the minimum stable depth of the
    study's first machining operation over the baseline's (NaN without the lobes stage); the
    margins are the truncation check's. The testbed columns
    (None without a run): the run's peak on its bins, the largest deviation from the sampled
    loop and the share of bins compared, and the run's speed.
    """

    position: str
    scenario: str
    peak_um_per_N: float
    peak_hz: float
    peak_reduction: float
    rms_reduction: float
    stable_depth_gain: float
    plant_margin: float
    check_margin: float
    sampled_loop: str
    measured_peak_um_per_N: float | None = None
    deviation_db: float | None = None
    period_difference: float | None = None
    steps_per_s: float | None = None


@dataclass
class ShareRow:
    """
    Share of the all-struts improvement that damping struts 1 and 2 achieves, at a position.

    By exact peak, by RMS of |H| over the band and by the grid's peak; with the testbed runs
    also the share by RMS measured from the bags and the RMS reductions it rests on.
    """

    position: str
    peak_share: float
    rms_share: float
    grid_peak_share: float
    measured_rms_share: float | None = None
    measured_rms_reduction_12: float | None = None
    measured_rms_reduction_all: float | None = None
    rms_reduction_12: float | None = None
    rms_reduction_all: float | None = None


def band(res: StudyResults) -> tuple[float, float]:
    """The band of peaks and RMS values [Hz]: excitation band start to f_max."""
    return float(res.cfg.band[0]), float(res.cfg.f_max)


def _analytic(res: StudyResults, pos: str, scn: str) -> ScenarioAnalytic:
    ana = res.analytic[(pos, scn)]
    assert ana.peak is not None and ana.loop is not None
    return ana


def _peak(ana: ScenarioAnalytic) -> float:
    assert ana.peak is not None
    return ana.peak.value


def _depth_gain(res: StudyResults, pos: str, scn: str) -> float:
    lobes, base = res.lobes.get((pos, scn)), res.lobes.get((pos, 'baseline'))
    if lobes is None or base is None:
        return math.nan
    return lobes.gain_over(base, res.cfg.machining_operations[0])


def summary_rows(res: StudyResults) -> list[SummaryRow]:
    """One row per (position, scenario) of the study file."""
    rows = []
    lo, hi = band(res)
    for pos in res.cfg.positions:
        base = _analytic(res, pos, 'baseline')
        _, base_rms = peak_and_rms(base.continuous, res.freq, lo, hi)
        for scn in res.cfg.scenarios:
            ana = _analytic(res, pos, scn)
            assert ana.peak is not None and ana.loop is not None
            _, rms = peak_and_rms(ana.continuous, res.freq, lo, hi)
            row = SummaryRow(pos, scn, ana.peak.value * 1e6, ana.peak.freq_hz,
                             _peak(base) / ana.peak.value, base_rms / rms,
                             _depth_gain(res, pos, scn), ana.loop.plant_margin,
                             ana.loop.check_margin, ana.loop.verdict)
            run = res.frf_runs.get((pos, scn))
            if run is not None:
                mes = run.measured
                inside = (mes.freq >= lo) & (mes.freq <= hi)
                row.measured_peak_um_per_N = float(np.abs(mes.h[inside]).max() * 1e6)
                row.deviation_db = run.deviation_db
                row.period_difference = mes.periodicity
                row.steps_per_s = mes.run.steps / mes.run.wall_time
            rows.append(row)
    return rows


def peak_rows(res: StudyResults) -> list[Row]:
    """Exact peaks (searched at the resonances) next to the peaks the frequency grid shows."""
    lo, hi = band(res)
    rows = []
    for pos in res.cfg.positions:
        base = _analytic(res, pos, 'baseline')
        base_grid = peak_and_rms(base.continuous, res.freq, lo, hi)[0]
        for scn in res.cfg.scenarios:
            ana = _analytic(res, pos, scn)
            assert ana.peak is not None
            grid = peak_and_rms(ana.continuous, res.freq, lo, hi)[0]
            rows.append({'position': pos, 'scenario': scn,
                         'peak_um_per_N': ana.peak.value * 1e6, 'peak_hz': ana.peak.freq_hz,
                         'grid_peak_um_per_N': grid * 1e6,
                         'peak_reduction': _peak(base) / ana.peak.value,
                         'grid_peak_reduction': base_grid / grid})
    return rows


def stability_rows(res: StudyResults) -> list[Row]:
    """Truncation check of every scenario's sampled loop: plant and check model."""
    rows = []
    for pos in res.cfg.positions:
        for scn in res.cfg.scenarios:
            loop = _analytic(res, pos, scn).loop
            assert loop is not None
            rows.append({'position': pos, 'scenario': scn, **loop.as_row()})
    return rows


def _rms(run: FrfRun, lo: float, hi: float) -> float:
    mes = run.measured
    return float(np.sqrt(np.mean(np.abs(mes.h[(mes.freq >= lo) & (mes.freq <= hi)]) ** 2)))


def struts12_share(res: StudyResults) -> list[ShareRow]:
    """Share of the all-struts improvement that damping struts 1 and 2 achieves."""
    lo, hi = band(res)
    rows = []
    names = ('baseline', 'strut_damping_12', 'strut_damping_all')   # improvement_share order
    for pos in res.cfg.positions:
        vals = {s: peak_and_rms(res.analytic[(pos, s)].continuous, res.freq, lo, hi)
                for s in names}
        exact = [_peak(res.analytic[(pos, s)]) for s in names]
        row = ShareRow(pos, improvement_share(*exact),
                       improvement_share(*(vals[s][1] for s in names)),
                       improvement_share(*(vals[s][0] for s in names)))
        if all((pos, s) in res.frf_runs for s in names):
            rms = {s: _rms(res.frf_runs[(pos, s)], lo, hi) for s in names}
            row.measured_rms_share = improvement_share(*(rms[s] for s in names))
            row.measured_rms_reduction_12 = rms['baseline'] / rms['strut_damping_12']
            row.measured_rms_reduction_all = rms['baseline'] / rms['strut_damping_all']
            row.rms_reduction_12 = vals['baseline'][1] / vals['strut_damping_12'][1]
            row.rms_reduction_all = vals['baseline'][1] / vals['strut_damping_all'][1]
        rows.append(row)
    return rows


def _pma_row(res: StudyResults, scn: str, design: PmaDesign, highpass: bool) -> Row:
    cfg = res.cfg
    row: Row = {'scenario': scn, 'proof_mass_kg': design.mass, 'gain_per_s': design.gain}
    if highpass:
        row['highpass_hz'] = design.highpass_hz
    row.update(requirement_row(design, cfg.pma_force_amplitude, band(res), cfg.pma_band,
                               cfg.pma_frequencies, res.freq))
    return row


def pma_rows(res: StudyResults) -> list[Row]:
    """
    Stroke and force of each PMA as run (ideal law).

    Worst cases over the excitation band and the stated band (exact), values at the stated
    frequencies, and what the bag measured.
    """
    lo, hi = band(res)
    rows = []
    for scn, req in res.pma.items():
        row = _pma_row(res, scn, req.ideal, False)
        run = res.frf_runs.get((res.cfg.step_position, scn))
        mes = run.measured if run is not None else None
        if mes is not None and mes.pma_stroke is not None and mes.pma_force is not None:
            inside = (mes.freq >= lo) & (mes.freq <= hi)
            amp = res.cfg.pma_force_amplitude
            row['measured_max_stroke_mm'] = float(np.abs(mes.pma_stroke[inside]).max() * amp
                                                  * 1e3)
            row['measured_max_force_N'] = float(np.abs(mes.pma_force[inside]).max() * amp)
        rows.append(row)
    return rows


def pma_highpass_rows(res: StudyResults) -> list[Row]:
    """
    The high-pass variant of each PMA.

    Its requirements as in :func:`pma_rows`, its largest stroke at any frequency (bounded,
    unlike the ideal law's), and its cost in TCP damping.
    """
    rows = []
    for scn, req in res.pma.items():
        row = _pma_row(res, scn, req.highpass, True)
        worst = bounded_stroke(req.highpass, res.cfg.pma_force_amplitude,
                               float(res.cfg.f_max))
        ideal = req.ideal.tcp_peak(*band(res)).value * 1e6
        row.update(any_freq_max_stroke_mm=worst.value * 1e3, any_freq_stroke_at_hz=worst.freq_hz,
                   ideal_tcp_peak_um_per_N=ideal,
                   tcp_peak_cost=row['tcp_peak_um_per_N'] / ideal)
        rows.append(row)
    return rows


def damping_rows(res: StudyResults) -> list[Row]:
    """
    Dominant modes of every loop: open-loop, sampled-loop, continuous-loop and identified ζ.

    Rows of the damping runs carry the identified frequency, damping ratio and peak; the
    other rows (other TCP directions, scenarios without a damping run) the analytic values.
    """
    out = []
    for key, ana in res.analytic.items():
        run = res.damping_runs.get(key)
        identified = {(m.analytic.direction, m.analytic.rank): m
                      for m in (run.modes if run is not None else [])}
        for mode in ana.modes:
            row = as_row(mode)
            found = identified.get((mode.direction, mode.rank))
            if found is not None:
                row.update(as_row(found))
            out.append({k: row.get(k, '') for k in DAMPING_COLUMNS})
    return out


def model_rows(res: StudyResults) -> list[Row]:
    """Per position: the FE model's DOF, the modes computed and kept, the check model."""
    rows: list[Row] = []
    for pos, m in res.models.items():
        check = m.check_plant
        rows.append({'position': pos, 'dof': m.plant.meta.get('n_dof'),
                     'modes_below_750_hz': m.plant.meta.get('n_modes_computed'),
                     'modes_kept': m.plant.n_modes,
                     'check_model_modes': check.n_modes if check else 0,
                     'check_model_below_hz': (check.meta.get('check_f_max_hz')
                                              if check else '-'),
                     'model_hash': m.model_hash[:12]})
    return rows


def is_measured(row: Row) -> bool:
    """A damping.csv row of a damping run (it has the identified columns)."""
    value = row.get('peak_analytic_um_per_N', '')
    return value != '' and not (isinstance(value, float) and math.isnan(value))
