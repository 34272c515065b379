"""Tables of the study and the Markdown report that shows them with the figures."""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
import time

import numpy as np

from pentapod_damper.study.analytic import improvement_share, peak_and_rms
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.measured_damping import SETTLE_MODES
from pentapod_damper.study.pma import bounded_stroke, requirement_row
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
    pma_designs: dict = field(default_factory=dict)  # scn -> {'ideal', 'highpass'}: PmaDesign
    figures: dict = field(default_factory=dict)      # caption -> path
    models: dict = field(default_factory=dict)      # pos -> PositionModel
    timings: dict = field(default_factory=dict)     # stage -> seconds
    scenario_gains: dict = field(default_factory=dict)   # bending model -> scenario gain
    bending_models: list = field(default_factory=list)   # rows of study.bending.compare
    bending_curves: dict = field(default_factory=dict)   # label -> peak reduction over gain
    damping: dict = field(default_factory=dict)          # (pos, scn) -> analytic pole rows
    damping_measured: dict = field(default_factory=dict)  # (pos, scn) -> rows with identified
    damping_figures: dict = field(default_factory=dict)  # run tag -> (stability, synthesis)
    out_dir: Path = Path('out/study')


def _band(res: StudyResults) -> tuple[float, float]:
    return float(res.cfg.band[0]), float(res.cfg.f_max)


def summary_rows(res: StudyResults) -> list[dict]:
    """
    One row per (position, scenario): exact peaks, reductions, margins, measured check.

    Peaks and peak reductions are exact (searched at the resonances); the RMS reduction is
    taken on the frequency grid; the margins are the truncation check's.
    """
    rows = []
    lo, hi = _band(res)
    for pos in res.cfg.positions:
        base = res.analytic[(pos, 'baseline')]
        _, base_rms = peak_and_rms(base.continuous, res.freq, lo, hi)
        for scn in res.cfg.scenarios:
            ana = res.analytic[(pos, scn)]
            _, rms = peak_and_rms(ana.continuous, res.freq, lo, hi)
            row = {'position': pos, 'scenario': scn, 'peak_um_per_N': ana.peak.value * 1e6,
                   'peak_hz': ana.peak.freq_hz, 'peak_reduction': base.peak.value / ana.peak.value,
                   'rms_reduction': base_rms / rms, 'plant_margin': ana.loop.plant_margin,
                   'check_margin': ana.loop.check_margin, 'sampled_loop': ana.loop.verdict}
            if (pos, scn) in res.measured:
                mes = res.measured[(pos, scn)]
                dev, share = res.deviation[(pos, scn)]
                band = (mes.freq >= lo) & (mes.freq <= hi)
                row.update(measured_peak_um_per_N=float(np.abs(mes.h[band]).max() * 1e6),
                           deviation_db=dev, compared_share=share,
                           steps_per_s=mes.run.steps / mes.run.wall_time)
            rows.append(row)
    return rows


def peak_rows(res: StudyResults) -> list[dict]:
    """Exact peaks (searched at the resonances) next to the peaks the frequency grid shows."""
    lo, hi = _band(res)
    rows = []
    for pos in res.cfg.positions:
        base = res.analytic[(pos, 'baseline')]
        base_grid = peak_and_rms(base.continuous, res.freq, lo, hi)[0]
        for scn in res.cfg.scenarios:
            ana = res.analytic[(pos, scn)]
            grid = peak_and_rms(ana.continuous, res.freq, lo, hi)[0]
            rows.append({'position': pos, 'scenario': scn,
                         'peak_um_per_N': ana.peak.value * 1e6, 'peak_hz': ana.peak.freq_hz,
                         'grid_peak_um_per_N': grid * 1e6,
                         'peak_reduction': base.peak.value / ana.peak.value,
                         'grid_peak_reduction': base_grid / grid})
    return rows


def stability_rows(res: StudyResults) -> list[dict]:
    """Truncation check of every scenario's sampled loop: plant and check model."""
    return [{'position': pos, 'scenario': scn, **res.analytic[(pos, scn)].loop.as_row()}
            for pos in res.cfg.positions for scn in res.cfg.scenarios]


def struts12_share(res: StudyResults) -> list[dict]:
    """Share of the all-struts improvement that damping struts 1 and 2 achieves."""
    lo, hi = _band(res)
    rows = []
    names = ('baseline', 'strut_damping_12', 'strut_damping_all')   # improvement_share order
    for pos in res.cfg.positions:
        vals = {s: peak_and_rms(res.analytic[(pos, s)].continuous, res.freq, lo, hi)
                for s in names}
        exact = {s: res.analytic[(pos, s)].peak.value for s in names}
        row = {'position': pos,
               'peak_share': improvement_share(*(exact[s] for s in names)),
               'rms_share': improvement_share(*(vals[s][1] for s in names)),
               'grid_peak_share': improvement_share(*(vals[s][0] for s in names))}
        if all((pos, s) in res.measured for s in vals):
            band = {s: res.measured[(pos, s)] for s in vals}
            rms = {s: float(np.sqrt(np.mean(np.abs(m.h[(m.freq >= lo) & (m.freq <= hi)]) ** 2)))
                   for s, m in band.items()}
            row['measured_rms_share'] = improvement_share(
                rms['baseline'], rms['strut_damping_12'], rms['strut_damping_all'])
            row['measured_rms_reduction_12'] = rms['baseline'] / rms['strut_damping_12']
            row['measured_rms_reduction_all'] = rms['baseline'] / rms['strut_damping_all']
            row['rms_reduction_12'] = vals['baseline'][1] / vals['strut_damping_12'][1]
            row['rms_reduction_all'] = vals['baseline'][1] / vals['strut_damping_all'][1]
        rows.append(row)
    return rows


def _pma_row(res: StudyResults, scn: str, variant: str) -> dict:
    cfg = res.cfg
    design = res.pma_designs[scn][variant]
    row = {'scenario': scn, 'proof_mass_kg': design.mass, 'gain_per_s': design.gain}
    if variant == 'highpass':
        row['highpass_hz'] = design.highpass_hz
    row.update(requirement_row(design, cfg.pma_force_amplitude, _band(res), cfg.pma_band,
                               cfg.pma_frequencies, res.freq))
    return row


def pma_rows(res: StudyResults) -> list[dict]:
    """
    Stroke and force of each PMA as run (ideal law).

    Worst cases over the excitation band and the stated band (exact), values at the stated
    frequencies, and what the bag measured.
    """
    lo, hi = _band(res)
    rows = []
    for scn in res.pma_designs:
        row = _pma_row(res, scn, 'ideal')
        mes = res.measured.get((res.cfg.step_position, scn))
        if mes is not None and mes.pma_stroke is not None:
            mb = (mes.freq >= lo) & (mes.freq <= hi)
            amp = res.cfg.pma_force_amplitude
            row['measured_max_stroke_mm'] = float(np.abs(mes.pma_stroke[mb]).max() * amp * 1e3)
            row['measured_max_force_N'] = float(np.abs(mes.pma_force[mb]).max() * amp)
        rows.append(row)
    return rows


def pma_highpass_rows(res: StudyResults) -> list[dict]:
    """
    The high-pass variant of each PMA.

    Its requirements as in :func:`pma_rows`, its largest stroke at any frequency (bounded,
    unlike the ideal law's), and its cost in TCP damping.
    """
    rows = []
    for scn, designs in res.pma_designs.items():
        row = _pma_row(res, scn, 'highpass')
        worst = bounded_stroke(designs['highpass'], res.cfg.pma_force_amplitude,
                               float(res.cfg.f_max))
        ideal = designs['ideal'].tcp_peak(*_band(res)).value * 1e6
        row.update(any_freq_max_stroke_mm=worst.value * 1e3, any_freq_stroke_at_hz=worst.freq_hz,
                   ideal_tcp_peak_um_per_N=ideal,
                   tcp_peak_cost=row['tcp_peak_um_per_N'] / ideal)
        rows.append(row)
    return rows


def damping_rows(res: StudyResults) -> list[dict]:
    """
    Dominant modes of every loop: open-loop, sampled-loop, continuous-loop and identified ζ.

    Rows of the damping runs carry the identified frequency, damping ratio and peak; the
    other rows (other TCP directions, scenarios without a damping run) the analytic values.
    """
    keep = ('position', 'scenario', 'direction', 'rank', 'mode', 'open_freq_hz', 'open_zeta',
            'sampled_freq_hz', 'sampled_zeta', 'continuous_zeta', 'sampled_mac',
            'measured_freq_hz', 'measured_zeta', 'zeta_error', 'freq_error',
            'peak_analytic_um_per_N', 'peak_measured_um_per_N', 'peak_error_db',
            'decay_time_s')
    out = []
    for key, rows in res.damping.items():
        measured = {(r['direction'], r['rank']): r for r in res.damping_measured.get(key, [])}
        for r in rows:
            r = measured.get((r['direction'], r['rank']), r)
            out.append({k: r.get(k, '') for k in keep})
    return out


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


def _stability_text(res: StudyResults) -> str:
    cfg = res.cfg
    return (
        'Spectral radius of the sampled loop (zero-order-hold plant, every law answering u_k '
        f'to y_k at {cfg.sample_rate:g} Hz) on the reduced plant and on a check model with '
        f'every FE mode below max({cfg.check_f_min:g} Hz, 2 x sample rate), same ports, no '
        'reduction (`pentapod_sim.sim.stability`). margin = 1 - spectral radius (> 0: '
        'stable); *_critical_hz: frequency of the largest eigenvalue. A loop that is stable on '
        'the plant but not on the check model is *stable only thanks to truncation*: the '
        'controller would excite modes the plant model left out, and its testbed run shows '
        'what the truncated model does, not what a machine would do. Policy: '
        f'`{cfg.check_policy}`. The margins of stable loops are small because the least damped '
        'mode (0.1 % modal damping) sets them.')


def _bending_text() -> str:
    return (
        "The paper's strut damper read two ways (continuous loop, ideal viscous dampers on "
        'both lateral axes of each strut): *rotational* = moment pair from the rotation of '
        'the WP end relative to the rear end (N m s/rad; the port spans the overhang behind '
        'the BP joint); *chord* = lateral force at mid-span against the chord between the '
        'joints (N s/m). optimal_gain minimises the all-struts exact peak (gain sweep, then '
        'a bounded search); reduction_*: exact peak reduction with all struts / struts 1+2; '
        'peak/rms_share_12: share of the all-struts improvement that struts 1+2 achieve, '
        'by exact peak and by RMS of |H| over the band; *_opt at the optimal gain, *_paper '
        "at the paper's b = 20,000 applied to each port as written.")


def _pma_text(res: StudyResults) -> str:
    cfg = res.cfg
    freqs = ', '.join(f'{f:g}' for f in cfg.pma_frequencies)
    return (
        f'Stroke and force amplitudes for a +-{cfg.pma_force_amplitude:g} N harmonic TCP force '
        f'at {cfg.step_position}, continuous closed loop, worst cases searched at the '
        f'resonances and band edges. max_*: over the excitation band {cfg.band[0]:g}-'
        f'{cfg.f_max:g} Hz; band_max_*: over the stated band {cfg.pma_band[0]:g}-'
        f'{cfg.pma_band[1]:g} Hz; *_at_<f>_hz: at the stated frequencies ({freqs} Hz); '
        'free_mass_stroke: F / (m_a w^2), the stroke if the proof mass took the whole force '
        "(the reading of the paper's 0.46 / 2.3 mm at 10.5 Hz). The ideal law's stroke grows "
        'as 1/f below the band, so its worst case sits at the lower band edge.')


def _damping_text(res: StudyResults) -> str:
    cfg = res.cfg
    return (
        'The three modes that dominate TCP aa (largest sampled-loop pole term between 2 and 200 '
        'Hz) per direction; open_zeta: the plant; sampled_zeta: the poles of the sampled loop '
        '(plant, laws, their dynamics and delay); continuous_zeta: the continuous loop without '
        'sampling; measured_zeta: identified (pLSCF + LSFD) from the damping run of the '
        f'scenario, a {cfg.damping_band[0]:g}-{cfg.damping_band[1]:g} Hz Schroeder multisine of '
        f'{cfg.damping_amplitude:g} N peak along {cfg.direction}, settled '
        f'{cfg.damping_time_constants:g} decay times of the slowest of the '
        f'{SETTLE_MODES} modes with the largest terms in the response, then '
        f'{cfg.damping_periods} periods of {cfg.damping_period:g} s averaged synchronously. '
        'Peaks: the identified FRF and the analytic sampled-loop FRF, each maximised near the '
        f'mode. Only the rows of the damping runs ({cfg.direction}{cfg.direction}) are shown; '
        'damping.csv has every loop and direction (analytic only).')


def write_report(res: StudyResults, out_dir: Path) -> Path:
    """Write report.md (and the tables as CSV) into ``out_dir``; return the report path."""
    cfg = res.cfg
    tables = {'summary': summary_rows(res), 'stability': stability_rows(res),
              'peaks': peak_rows(res), 'struts12_share': struts12_share(res),
              'bending_models': res.bending_models,
              'pma': pma_rows(res), 'pma_highpass': pma_highpass_rows(res),
              'damping': damping_rows(res)}
    for name, rows in tables.items():
        write_csv(rows, out_dir / f'{name}.csv')
    models = [{'position': p, 'dof': m.plant.meta.get('n_dof'),
               'modes_below_750_hz': m.plant.meta.get('n_modes_computed'),
               'modes_kept': m.plant.n_modes,
               'check_model_modes': m.check_plant.n_modes if m.check_plant else 0,
               'check_model_below_hz': (m.check_plant.meta.get('check_f_max_hz')
                                        if m.check_plant else '-'),
               'model_hash': m.model_hash[:12]}
              for p, m in res.models.items()]
    lines = [
        '# Damping study of the pentapod on the virtual testbed', '',
        f'Generated {time.strftime("%Y-%m-%d %H:%M")} by pentapod_testbed {__version__} '
        f'(`python -m pentapod_damper.study`). Every row marked *testbed run* comes from a '
        f'lockstep ROS 2 run (plant, exciter, controllers and recorder composed in one process, '
        f'bit-identical to separate processes) '
        f'recorded to an MCAP bag; the bags and the parameter file of each run are under '
        f'`runs/`.', '',
        f'Excitation: random force at the TCP in {cfg.direction}, {cfg.amplitude:g} N RMS, '
        f'{cfg.band[0]:g}-{cfg.band[1]:g} Hz, {cfg.duration:g} s at {cfg.sample_rate:g} Hz '
        '(plain sampled feedback: zero-order hold, each law answers u_k to the outputs y_k of '
        f'the same step). FRFs are TCP displacement / TCP force [um/N] in {cfg.direction}; '
        'modal damping 0.1 %.', '',
        '## Models', '', markdown_table(models), '',
        '## Summary', '',
        'peak_um_per_N and peak_reduction: exact peaks of the analytic continuous model over '
        f'{cfg.band[0]:g}-{cfg.f_max:g} Hz, searched at every resonance (see *Exact peaks*); '
        'rms_reduction: RMS of |H| on the frequency grid; plant/check_margin and sampled_loop: '
        'truncation check (next section). deviation_db: largest difference between the FRF '
        'measured from the bag and the analytic FRF of the sampled loop, over bins with '
        f'coherence >= {cfg.coherence_min}; compared_share: share of bins compared.', '',
        markdown_table(tables['summary']), '',
        '## Sampled-loop stability (truncation check)', '', _stability_text(res), '',
        markdown_table(tables['stability']), '',
        '## Exact peaks and the frequency grid', '',
        f'The analytic grid has {res.freq.size} points ({res.freq[1] - res.freq[0]:.3g} Hz '
        'apart); a 0.1 %-damped resonance is 2 zeta f wide at half power (0.05 Hz at 27 Hz), '
        'so the grid misses its top. Exact peaks maximise |H| with a bounded scalar search '
        'near the damped frequency of every pole in the band (plus the band edges).', '',
        markdown_table(tables['peaks']), '',
        '## Struts 1 and 2', '',
        'Share of the improvement of damping all struts that damping struts 1 and 2 alone '
        'achieves (1 = all of it), by exact peak, by RMS of |H| over the band, and by the '
        'grid peak (for comparison).', '',
        markdown_table(tables['struts12_share']), '',
        '## Two strut bending damper models', '', _bending_text(), '',
        markdown_table(tables['bending_models']), '',
        '## Proof-mass actuators', '', _pma_text(res), '', markdown_table(tables['pma']), '',
        f'High-pass variant (2nd-order Butterworth at {cfg.pma_highpass_hz:g} Hz on the mount '
        'velocity): any_freq_max_stroke is its largest stroke at any frequency up to '
        f'{cfg.f_max:g} Hz (bounded: below the corner the proof mass stops following); '
        'tcp_peak_cost: its exact TCP peak over that of the ideal law.', '',
        markdown_table(tables['pma_highpass']), '',
        '## Damping per mode', '', _damping_text(res), '',
        markdown_table([r for r in tables['damping'] if (r['position'], r['scenario'])
                        in res.damping_measured]), '',
        '## Figures', '']
    for caption, path in res.figures.items():
        lines += [f'### {caption}', '', f'![{caption}]({Path(path).relative_to(out_dir)})', '']
    lines += ['## Timings', '', markdown_table([{'stage': k, 'seconds': v}
                                                 for k, v in res.timings.items()]), '']
    path = out_dir / 'report.md'
    path.write_text('\n'.join(lines))
    return path
