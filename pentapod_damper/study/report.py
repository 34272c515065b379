"""Tables of the study and the Markdown report that shows them with the figures."""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
import time

import numpy as np

from pentapod_damper.study.analytic import improvement_share, peak_and_rms
from pentapod_damper.study.config import StudyConfig
from pentapod_sim import __version__


@dataclass
class StudyResults:
    """Everything the report shows, filled by :mod:`pentapod_damper.study.__main__`."""

    cfg: StudyConfig
    freq: np.ndarray
    analytic: dict = field(default_factory=dict)     # (pos, scn) -> ScenarioAnalytic
    measured: dict = field(default_factory=dict)     # (pos, scn) -> Measured
    deviation: dict = field(default_factory=dict)    # (pos, scn) -> (max dB, share compared)
    pma: dict = field(default_factory=dict)          # scn -> (stroke, force) analytic, step pos
    figures: dict = field(default_factory=dict)      # caption -> path
    models: dict = field(default_factory=dict)      # pos -> PositionModel
    timings: dict = field(default_factory=dict)     # stage -> seconds
    bending_gain: float = float('nan')
    out_dir: Path = Path('out/study')


def _band(res: StudyResults) -> tuple[float, float]:
    return float(res.cfg.band[0]), float(res.cfg.f_max)


def summary_rows(res: StudyResults) -> list[dict]:
    """One row per (position, scenario): analytic peaks and reductions, measured check."""
    rows = []
    lo, hi = _band(res)
    for pos in res.cfg.positions:
        base_peak, base_rms = peak_and_rms(res.analytic[(pos, 'baseline')].continuous,
                                           res.freq, lo, hi)
        for scn in res.cfg.scenarios:
            peak, rms = peak_and_rms(res.analytic[(pos, scn)].continuous, res.freq, lo, hi)
            row = {'position': pos, 'scenario': scn, 'peak_um_per_N': peak * 1e6,
                   'peak_reduction': base_peak / peak, 'rms_reduction': base_rms / rms}
            if (pos, scn) in res.measured:
                mes = res.measured[(pos, scn)]
                dev, share = res.deviation[(pos, scn)]
                band = (mes.freq >= lo) & (mes.freq <= hi)
                row.update(measured_peak_um_per_N=float(np.abs(mes.h[band]).max() * 1e6),
                           deviation_db=dev, compared_share=share,
                           steps_per_s=mes.run.steps / mes.run.wall_time)
            rows.append(row)
    return rows


def struts12_share(res: StudyResults) -> list[dict]:
    """Share of the all-struts improvement that damping struts 1 and 2 achieves."""
    lo, hi = _band(res)
    rows = []
    for pos in res.cfg.positions:
        vals = {s: peak_and_rms(res.analytic[(pos, s)].continuous, res.freq, lo, hi)
                for s in ('baseline', 'strut_damping_all', 'strut_damping_12')}
        row = {'position': pos,
               'peak_share': improvement_share(vals['baseline'][0], vals['strut_damping_12'][0],
                                               vals['strut_damping_all'][0]),
               'rms_share': improvement_share(vals['baseline'][1], vals['strut_damping_12'][1],
                                              vals['strut_damping_all'][1])}
        if all((pos, s) in res.measured for s in vals):
            band = {s: res.measured[(pos, s)] for s in vals}
            rms = {s: float(np.sqrt(np.mean(np.abs(m.h[(m.freq >= lo) & (m.freq <= hi)]) ** 2)))
                   for s, m in band.items()}
            row['measured_rms_share'] = improvement_share(
                rms['baseline'], rms['strut_damping_12'], rms['strut_damping_all'])
        rows.append(row)
    return rows


def pma_rows(res: StudyResults) -> list[dict]:
    """Largest stroke and force of each PMA over the band, analytic and measured."""
    lo, hi = _band(res)
    band = (res.freq >= lo) & (res.freq <= hi)
    rows = []
    for scn, (stroke, force) in res.pma.items():
        ana = res.analytic[(res.cfg.step_position, scn)]
        row = {'scenario': scn, 'proof_mass_kg': ana.pma['mass'], 'gain_per_s': ana.pma['gain'],
               'max_stroke_mm': float(stroke[band].max() * 1e3),
               'at_hz': float(res.freq[band][np.argmax(stroke[band])]),
               'max_force_N': float(force[band].max())}
        mes = res.measured.get((res.cfg.step_position, scn))
        if mes is not None and mes.pma_stroke is not None:
            mb = (mes.freq >= lo) & (mes.freq <= hi)
            amp = res.cfg.pma_force_amplitude
            row['measured_max_stroke_mm'] = float(np.abs(mes.pma_stroke[mb]).max() * amp * 1e3)
            row['measured_max_force_N'] = float(np.abs(mes.pma_force[mb]).max() * amp)
        rows.append(row)
    return rows


def _fmt(v) -> str:
    if isinstance(v, float):
        return '-' if not np.isfinite(v) else f'{v:.3g}'
    return str(v)


def markdown_table(rows: list[dict]) -> str:
    """Rows of dicts as a Markdown table (columns of the first row)."""
    if not rows:
        return '(none)'
    cols = list(dict.fromkeys(k for r in rows for k in r))
    lines = ['| ' + ' | '.join(cols) + ' |', '|' + '---|' * len(cols)]
    lines += ['| ' + ' | '.join(_fmt(r.get(c, '-')) for c in cols) + ' |' for r in rows]
    return '\n'.join(lines)


def write_csv(rows: list[dict], path: Path) -> Path:
    """Write rows of dicts as CSV."""
    cols = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=cols)
        writer.writeheader()
        writer.writerows(rows)
    return path


def write_report(res: StudyResults, out_dir: Path) -> Path:
    """Write report.md (and the tables as CSV) into ``out_dir``; return the report path."""
    cfg = res.cfg
    summary, share, pma = summary_rows(res), struts12_share(res), pma_rows(res)
    for name, rows in (('summary', summary), ('struts12_share', share), ('pma', pma)):
        write_csv(rows, out_dir / f'{name}.csv')
    models = [{'position': p, 'dof': m.plant.meta.get('n_dof'),
               'modes_below_750_hz': m.plant.meta.get('n_modes_computed'),
               'modes_kept': m.plant.n_modes, 'model_hash': m.model_hash[:12]}
              for p, m in res.models.items()]
    lines = [
        '# Damping study of the pentapod on the virtual testbed', '',
        f'Generated {time.strftime("%Y-%m-%d %H:%M")} by pentapod_testbed {__version__} '
        f'(`python -m pentapod_damper.study`). Every row marked *testbed run* comes from a '
        f'lockstep ROS 2 run (plant, exciter, controllers and recorder as separate processes) '
        f'recorded to an MCAP bag; the bags and the parameter file of each run are under '
        f'`runs/`.', '',
        f'Excitation: random force at the TCP in {cfg.direction}, {cfg.amplitude:g} N RMS, '
        f'{cfg.band[0]:g}-{cfg.band[1]:g} Hz, {cfg.duration:g} s at {cfg.sample_rate:g} Hz '
        f'(controllers act one sample late). FRFs are TCP displacement / TCP force '
        f'[um/N] in {cfg.direction}; modal damping 0.1 %.', '',
        '## Models', '', markdown_table(models), '',
        '## Summary', '',
        'peak/rms_reduction: baseline over damped, analytic continuous model, '
        f'{cfg.band[0]:g}-{cfg.f_max:g} Hz. deviation_db: largest difference between the FRF '
        'measured from the bag and the analytic FRF of the sampled loop, over bins with '
        f'coherence >= {cfg.coherence_min}; compared_share: share of bins compared.', '',
        markdown_table(summary), '',
        '## Struts 1 and 2', '',
        'Share of the improvement of damping all struts that damping struts 1 and 2 alone '
        'achieves (1 = all of it), by peak and by RMS of |H| over the band.', '',
        markdown_table(share), '',
        '## Proof-mass actuators', '',
        f'Stroke and force amplitudes for a +-{cfg.pma_force_amplitude:g} N harmonic TCP force '
        f'at {cfg.step_position}.', '', markdown_table(pma), '',
        '## Figures', '']
    for caption, path in res.figures.items():
        lines += [f'### {caption}', '', f'![{caption}]({Path(path).relative_to(out_dir)})', '']
    lines += ['## Timings', '', markdown_table([{'stage': k, 'seconds': v}
                                                 for k, v in res.timings.items()]), '']
    path = out_dir / 'report.md'
    path.write_text('\n'.join(lines))
    return path
