"""
The study's report: its tables as CSV files and report.md, made from those files alone.

:func:`write_report` writes every table of :mod:`pentapod_damper.study.tables` (and those the
stages add, :class:`~pentapod_damper.study.records.Table`) as ``<name>.csv`` into the output
folder, with ``models.csv``, ``figures.csv`` and ``timings.csv``, then renders report.md from
these files and the study file. So ``python -m pentapod_damper.study report`` makes the same
report again from a finished run's folder, e.g. after the text changed.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
import time
from typing import Iterable

from pentapod_damper.study import tables
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.records import as_row, Row, settling_text, StudyResults
from pentapod_sim import __version__

#: The report's tables, in its order (CSV files of the output folder).
TABLES = ('summary', 'stability', 'peaks', 'struts12_share', 'bending_models', 'pma',
          'pma_highpass', 'damping')
#: What the report shows besides the tables: models, figures (caption, file), timings, and
#: the title and text of each table a stage added.
EXTRA = ('models', 'figures', 'timings', 'stage_tables')


def study_tables(res: StudyResults) -> dict[str, list[Row]]:
    """Every table of the report, by CSV name."""
    return {'summary': [as_row(r) for r in tables.summary_rows(res)],
            'stability': tables.stability_rows(res), 'peaks': tables.peak_rows(res),
            'struts12_share': [as_row(r) for r in tables.struts12_share(res)],
            'bending_models': [as_row(m) for c in res.bending.values() for m in c.models],
            'pma': tables.pma_rows(res), 'pma_highpass': tables.pma_highpass_rows(res),
            'damping': tables.damping_rows(res),
            'models': tables.model_rows(res),
            'figures': [{'caption': caption, 'file': path.relative_to(res.out_dir).as_posix()}
                        for group in res.figures for caption, path in group.paths.items()],
            'timings': [{'stage': k, 'seconds': v} for k, v in res.timings.items()],
            'stage_tables': [{'name': t.name, 'title': t.title, 'text': t.text}
                             for t in res.tables],
            **{t.name: t.rows for t in res.tables}}


def write_csv(rows: Iterable[Row], path: Path) -> Path:
    """Write rows of dicts as CSV (the columns of every row, in the order first seen)."""
    rows = list(rows)
    cols = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=cols)
        writer.writeheader()
        writer.writerows(rows)
    return path


def read_csv(path: Path) -> list[dict[str, str]]:
    """Rows of a CSV table as dicts of strings."""
    with open(path, newline='') as stream:
        return list(csv.DictReader(stream))


def cell(text: str) -> str:
    """A CSV cell as the report shows it: numbers with 3 digits, '-' for none."""
    if text in ('', 'nan', 'inf', '-inf'):
        return '-'
    try:
        return str(int(text))
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return text
    return f'{value:.3g}' if math.isfinite(value) else '-'


def markdown_table(rows: list[dict[str, str]]) -> str:
    """Rows read from a CSV file as a Markdown table."""
    if not rows:
        return '(none)'
    cols = list(rows[0])
    lines = ['| ' + ' | '.join(cols) + ' |', '|' + '---|' * len(cols)]
    lines += ['| ' + ' | '.join(cell(r.get(c) or '') for c in cols) + ' |' for r in rows]
    return '\n'.join(lines)


def write_report(res: StudyResults, out_dir: Path) -> Path:
    """Write every table as CSV into ``out_dir``, then report.md from them; its path."""
    for name, rows in study_tables(res).items():
        write_csv(rows, out_dir / f'{name}.csv')
    return rewrite_report(out_dir, res.cfg)


def rewrite_report(out_dir: Path, cfg: StudyConfig) -> Path:
    """
    Make report.md of a study's output folder from its CSV files.

    Raises
    ------
    OSError
        If a table is missing (the message names the file).
    """
    path = out_dir / 'report.md'
    path.write_text(render(out_dir, cfg))
    return path


def render(out_dir: Path, cfg: StudyConfig) -> str:
    """The text of report.md from the CSV files in ``out_dir``."""
    t = {name: read_csv(out_dir / f'{name}.csv') for name in TABLES + EXTRA}
    lo, hi = float(cfg.band[0]), float(cfg.f_max)
    f_min, f_max, n_points = cfg.freq_grid
    lines = [
        '# Damping study of the pentapod on the virtual testbed', '',
        f'Generated {time.strftime("%Y-%m-%d %H:%M")} by pentapod_testbed {__version__} '
        f'(`python -m pentapod_damper.study`). Every row marked *testbed run* comes from a '
        f'lockstep ROS 2 run (plant, exciter, controllers and recorder composed in one process, '
        f'bit-identical to separate processes) '
        f'recorded to an MCAP bag; the bags and the parameter file of each run are under '
        f'`runs/`.', '',
        f'Excitation: multisine force at the TCP in {cfg.direction}, {cfg.amplitude:g} N peak, '
        f'lines every {1 / cfg.period:g} Hz over {cfg.band[0]:g}-{cfg.band[1]:g} Hz, '
        f'{cfg.periods} periods of {cfg.period:g} s from the periodic steady state of the '
        f'linear loop, at {cfg.sample_rate:g} Hz '
        '(plain sampled feedback: zero-order hold, each law answers u_k to the outputs y_k of '
        f'the same step). FRFs are TCP displacement / TCP force [um/N] in {cfg.direction}; '
        'modal damping 0.1 %.', '',
        '## Models', '', markdown_table(t['models']), '',
        '## Summary', '',
        'peak_um_per_N and peak_reduction: exact peaks of the analytic continuous model over '
        f'{lo:g}-{hi:g} Hz, searched at every resonance (see *Exact peaks*); '
        'rms_reduction: RMS of |H| on the frequency grid; plant/check_margin and sampled_loop: '
        'truncation check (next section). deviation_db: largest difference between the FRF '
        'measured from the bag and the analytic FRF of the sampled loop, over every line; '
        'period_difference: largest difference between the first and last recorded period '
        'of the TCP displacement, relative to its peak.', '',
        markdown_table(t['summary']), '',
        '## Sampled-loop stability (truncation check)', '', _stability_text(cfg), '',
        markdown_table(t['stability']), '',
        '## Exact peaks and the frequency grid', '',
        f'The analytic grid has {int(n_points)} points ({(f_max - f_min) / (n_points - 1):.3g} '
        'Hz apart); a 0.1 %-damped resonance is 2 zeta f wide at half power (0.05 Hz at '
        '27 Hz), so the grid misses its top. Exact peaks maximise |H| with a bounded scalar '
        'search near the damped frequency of every pole in the band (plus the band edges).',
        '', markdown_table(t['peaks']), '',
        '## Struts 1 and 2', '',
        'Share of the improvement of damping all struts that damping struts 1 and 2 alone '
        'achieves (1 = all of it), by exact peak, by RMS of |H| over the band, and by the '
        'grid peak (for comparison).', '',
        markdown_table(t['struts12_share']), '',
        '## Two strut bending damper models', '', _BENDING_TEXT, '',
        markdown_table(t['bending_models']), '',
        '## Proof-mass actuators', '', _pma_text(cfg), '', markdown_table(t['pma']), '',
        f'High-pass variant (2nd-order Butterworth at {cfg.pma_highpass_hz:g} Hz on the mount '
        'velocity): any_freq_max_stroke is its largest stroke at any frequency up to '
        f'{hi:g} Hz (bounded: below the corner the proof mass stops following); '
        'tcp_peak_cost: its exact TCP peak over that of the ideal law.', '',
        markdown_table(t['pma_highpass']), '',
        '## Damping per mode', '', _damping_text(cfg), '',
        markdown_table([r for r in t['damping'] if tables.is_measured(r)]), '']
    for extra in t['stage_tables']:
        lines += [f'## {extra["title"]}', '', extra['text'], '',
                  markdown_table(read_csv(out_dir / f'{extra["name"]}.csv')), '']
    lines += ['## Figures', '']
    for figure in t['figures']:
        lines += [f'### {figure["caption"]}', '', f'![{figure["caption"]}]({figure["file"]})',
                  '']
    lines += ['## Timings', '', markdown_table(t['timings']), '']
    return '\n'.join(lines)


def _stability_text(cfg: StudyConfig) -> str:
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


_BENDING_TEXT = (
    "The paper's strut damper read two ways (continuous loop, ideal viscous dampers on "
    'both lateral axes of each strut): *rotational* = moment pair from the rotation of '
    'the WP end relative to the rear end (N m s/rad; the port spans the overhang behind '
    'the BP joint); *chord* = lateral force at mid-span against the chord between the '
    'joints (N s/m). optimal_gain minimises the all-struts exact peak (gain sweep, then '
    'a bounded search); reduction_*: exact peak reduction with all struts / struts 1+2; '
    'peak/rms_share_12: share of the all-struts improvement that struts 1+2 achieve, '
    'by exact peak and by RMS of |H| over the band; *_opt at the optimal gain, *_paper '
    "at the paper's b = 20,000 applied to each port as written.")


def _pma_text(cfg: StudyConfig) -> str:
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


def _damping_text(cfg: StudyConfig) -> str:
    return (
        'The three modes that dominate TCP aa (largest sampled-loop pole term between 2 and 200 '
        'Hz) per direction; open_zeta: the plant; sampled_zeta: the poles of the sampled loop '
        '(plant, laws, their dynamics and delay); continuous_zeta: the continuous loop without '
        'sampling; measured_zeta: identified (pLSCF + LSFD) from the damping run of the '
        f'scenario, a {cfg.damping_band[0]:g}-{cfg.damping_band[1]:g} Hz Schroeder multisine of '
        f'{cfg.damping_amplitude:g} N peak along {cfg.direction}, {settling_text(cfg)}, then '
        f'{cfg.damping_periods} periods of {cfg.damping_period:g} s averaged synchronously. '
        'Peaks: the identified FRF and the analytic sampled-loop FRF, each maximised near the '
        f'mode. Only the rows of the damping runs ({cfg.direction}{cfg.direction}) are shown; '
        'damping.csv has every loop and direction (analytic only).')


def missing_tables(out_dir: Path) -> list[str]:
    """The CSV files report.md needs that ``out_dir`` lacks."""
    return [f'{n}.csv' for n in TABLES + EXTRA if not (out_dir / f'{n}.csv').is_file()]
