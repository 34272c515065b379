"""
The study's generated docs: the tables of docs/results.md and the result sentences of the README.

``python -m pentapod_damper.study docs --from out/study`` copies the CSV tables of a study run
(``python -m pentapod_damper.study``) to ``docs/results/``, refreshes the study figures that
``docs/figures/`` holds, and rewrites, from the copies, the section between
``<!-- study-tables:begin -->`` and ``<!-- study-tables:end -->`` of docs/results.md and the
README's ``study-summary`` section (no hand-typed result in either). Without ``--from`` it only
rewrites the two sections. test/test_docs.py checks that both equal what this makes from
``docs/results/`` and that the analytic columns there equal what the current code and
``config/study.yaml`` compute.
"""
from __future__ import annotations

import math
from pathlib import Path
import shutil
import textwrap

from pentapod_damper.study.claim import claim_sentences, PAPER_SHARE
from pentapod_damper.study.claim import where as _where
from pentapod_damper.study.config import load_study_config, StudyConfig
from pentapod_damper.study.records import settling_text
from pentapod_damper.study.report import read_csv
from pentapod_damper.study.strut_laws import TABLE as STRUT_LAWS
from pentapod_sim.reference import replace_section

#: section of docs/results.md with the tables, section of the README with the sentences
SECTION, SUMMARY = 'study-tables', 'study-summary'
#: scenarios the README's sentence on peak reductions names, and how
SUMMARY_SCENARIOS = (('tcp_damping', 'TCP damper'), ('pma_5kg', '5 kg PMA'),
                     ('strut_damping_all', 'bending dampers on all struts'),
                     ('axial_damping', 'axial dampers'))
TABLES = ('summary', 'struts12_share', 'pma', 'pma_highpass', 'damping', STRUT_LAWS)
#: Tables a study run may lack (the damper table's laws: not run on an imported FE model).
OPTIONAL = (STRUT_LAWS,)
COMMAND = 'python -m pentapod_damper.study docs'
Columns = tuple[tuple[str, str, str], ...]
#: (CSV column, header in docs/results.md, format) of each table; columns a run lacks show '-'.
COLUMNS: dict[str, Columns] = {
    'summary': (('position', 'position', 's'), ('scenario', 'scenario', 'code'),
                ('peak_um_per_N', 'peak [um/N]', '.3g'), ('peak_hz', 'at [Hz]', '.3g'),
                ('peak_reduction', 'peak reduction', '.3g'),
                ('rms_reduction', 'RMS reduction', '.3g'),
                ('stable_depth_gain', 'stable depth gain', '.3g'),
                ('sampled_loop', 'sampled loop', 's'),
                ('deviation_db', 'testbed dev. [dB]', '.2g'),
                ('period_difference', 'periods differ', '.1e')),
    'struts12_share': (('position', 'position', 's'), ('peak_share', 'by peak', '%'),
                       ('rms_share', 'by RMS', '%'),
                       ('rms_reduction_12', 'RMS reduction, struts 1+2', '.3g'),
                       ('rms_reduction_all', 'RMS reduction, all', '.3g'),
                       ('measured_rms_share', 'by RMS, measured from the bags', '%'),
                       ('measured_rms_reduction_12', 'measured RMS reduction, struts 1+2',
                        '.3g'),
                       ('measured_rms_reduction_all', 'measured RMS reduction, all', '.3g')),
    'pma': (('scenario', 'scenario', 'code'), ('proof_mass_kg', 'proof mass [kg]', 'g'),
            ('gain_per_s', 'gain [1/s]', 'g'), ('max_stroke_mm', 'largest stroke [mm]', '.3g'),
            ('at_hz', 'at [Hz]', '.3g'), ('max_force_N', 'largest force [N]', '.3g'),
            ('band_max_stroke_mm', 'largest stroke in the PMA band [mm]', '.3g'),
            ('measured_max_stroke_mm', 'stroke from the bag [mm]', '.3g'),
            ('measured_max_force_N', 'force from the bag [N]', '.3g')),
    'pma_highpass': (('scenario', 'scenario', 'code'), ('highpass_hz', 'high-pass [Hz]', 'g'),
                     ('any_freq_max_stroke_mm', 'largest stroke, any frequency [mm]', '.3g'),
                     ('any_freq_stroke_at_hz', 'at [Hz]', '.3g'),
                     ('tcp_peak_cost', "TCP peak / ideal PMA's", '.3g')),
    STRUT_LAWS: (('position', 'position', 's'), ('law', 'law', 's'),
                 ('gains_tuned_at', 'gains tuned at', 's'),
                 ('sample_rate_hz', 'rate [Hz]', 'g'), ('delay_steps', 'delay [samples]', 's'),
                 ('plant_modes', 'plant modes', 's'), ('drives', "drives' rotors", 's'),
                 ('peak_reduction', 'peak reduction', '.3g'),
                 ('rms_reduction', 'RMS reduction', '.3g'),
                 ('peak_reduction_12', 'peak reduction, struts 1+2', '.3g'),
                 ('rms_reduction_12', 'RMS reduction, struts 1+2', '.3g'),
                 ('struts12_share_peak', 'share by peak', '%'),
                 ('struts12_share_rms', 'share by RMS', '%')),
    'damping': (('position', 'position', 's'), ('scenario', 'scenario', 'code'),
                ('mode', 'mode', 's'), ('fe_mode', 'FE mode', 's'), ('cause', 'cause', 's'),
                ('sampled_freq_hz', 'f [Hz]', '.4g'),
                ('open_zeta', 'ζ open loop', '.3g'),
                ('sampled_zeta', 'ζ closed loop, analytic', '.3g'),
                ('continuous_zeta', 'ζ continuous loop', '.3g'),
                ('measured_zeta', 'ζ identified from the run', '.3g'),
                ('zeta_error', 'ζ error', '+.1%'), ('freq_error', 'f error', '+.3%'),
                ('peak_analytic_um_per_N', 'peak, analytic [um/N]', '.3g'),
                ('peak_error_db', 'peak, identified - analytic [dB]', '+.2f')),
}


def _cell(text: str | None, kind: str) -> str:
    if text is None or text == '':
        return '-'
    if kind == 's':
        return text
    if kind == 'code':
        return f'`{text}`'
    value = float(text)
    if not math.isfinite(value):
        return '-'
    return f'{value:.0%}' if kind == '%' else format(value, kind)


def _damping_rows(rows: list[dict[str, str]], cfg: StudyConfig) -> list[dict[str, str]]:
    """The rows of the damping runs: their scenarios, the excited direction."""
    d = cfg.direction
    return [r for r in rows if r['scenario'] in cfg.damping_scenarios
            and r['direction'] == d + d]


def markdown_table(rows: list[dict[str, str]], columns: Columns) -> str:
    """Selected CSV columns as a Markdown table with the headers and formats of COLUMNS."""
    lines = ['| ' + ' | '.join(c[1] for c in columns) + ' |', '|' + '---|' * len(columns)]
    lines += ['| ' + ' | '.join(_cell(r.get(key), kind) for key, _, kind in columns) + ' |'
              for r in rows]
    return '\n'.join(lines)


def study_section(results: Path, cfg: StudyConfig) -> str:
    """The study tables of docs/results.md from the CSV copies in ``results``."""
    tables = {name: read_csv(results / f'{name}.csv') for name in TABLES
              if name not in OPTIONAL or (results / f'{name}.csv').is_file()}
    d, (lo, _) = cfg.direction, cfg.band
    return '\n\n'.join([
        _prose(f'(generated by `{COMMAND}` from `docs/results/*.csv`, the CSV tables of the last '
               '`python -m pentapod_damper.study` run' + (
                   ')' if _has_testbed_runs(tables['summary']) else
                   ', which was `--analytic-only`: the testbed columns are empty until a full '
                   'run is copied)')),
        _prose(f'TCP {d}{d} compliance (displacement/force) between {lo:g} and {cfg.f_max:g} Hz, '
               'analytic continuous model; peaks are exact (searched at the resonances), RMS '
               'values on the frequency grid, reductions are baseline over damped. *sampled '
               'loop* is the verdict of the truncation check (`pentapod_sim/sim/stability.py`): '
               '"stable only thanks to truncation" means the loop is stable with the reduced '
               'plant but not with every FE mode up to the check frequency. *testbed dev.* is '
               'the largest difference between the FRF measured from the recorded run and the '
               'analytic FRF of the sampled loop, over every line of the multisine '
               f'({cfg.amplitude:g} N peak, lines every {1 / cfg.period:g} Hz from '
               f'{cfg.band[0]:g} to {cfg.band[1]:g} Hz, {cfg.periods} periods of '
               f'{cfg.period:g} s averaged after {cfg.settle_periods} discarded, '
               f'{cfg.duration * cfg.sample_rate:.0f} steps per run at {cfg.sample_rate:g} Hz). '
               'What it rests on: each run starts at the periodic steady state computed from '
               'the linear model of the loop (plant and laws), so the 0.1 %-damped modes need '
               "no settling and every line is resolved. The laws' nodes start at rest, so the "
               'plant starts shifted from that state such that the difference excites only the '
               "loop's fastest modes (the laws' filters, gone within milliseconds), and the "
               'discarded period holds that. The deviation then measures how far the testbed '
               'departs from the linear model over the periods averaged. *periods differ* '
               'is the periodicity check: the largest difference between the first and the last '
               'recorded period of the TCP displacement, relative to its peak; a transient (a '
               "start that is not the testbed's steady state) would show there. Lines are "
               f'{1 / cfg.period:g} Hz apart: a peak narrower than that (0.1 % at 27 Hz: '
               '0.05 Hz) is compared at the lines beside it, not at its top (the *peak* column '
               'gives the exact one).'),
        markdown_table(tables['summary'], COLUMNS['summary']),
        _prose('Share of the improvement of damping all struts that damping struts 1 and 2 '
               'alone achieves (100% = all of it), with the buildable strut dampers of the '
               'scenarios. The share measured from the bags divides two small differences of '
               f'RMS values of FRFs measured at the multisine lines ({1 / cfg.period:g} Hz apart,'
               ' beside the narrow peaks of the 0.1 %-damped modes); where the measured '
               'RMS reductions stray from the analytic ones by more than the improvements '
               'themselves, it does not resolve the share (it can even come out negative):'),
        markdown_table(tables['struts12_share'], COLUMNS['struts12_share']),
        *_strut_laws_part(results, tables.get(STRUT_LAWS)),
        _prose(f'Proof-mass actuators at {cfg.step_position} for a +-{cfg.pma_force_amplitude:g}'
               f' N harmonic TCP force, largest values over {lo:g}-{cfg.f_max:g} Hz and in the '
               f'PMA band {cfg.pma_band[0]:g}-{cfg.pma_band[1]:g} Hz (ideal law, as run):'),
        markdown_table(tables['pma'], COLUMNS['pma']),
        _prose('The same PMAs with a 2nd-order Butterworth high-pass on the mount velocity '
               '(bounded stroke) and what it costs in TCP damping:'),
        markdown_table(tables['pma_highpass'], COLUMNS['pma_highpass']),
        _prose(f'Damping per mode: the three modes that dominate TCP {d}{d} in 2-200 Hz, with '
               'the damping ratio of the plant, of the sampled closed loop (its poles: plant, '
               'laws, their dynamics and delay), of the continuous loop without sampling, and '
               'identified (pLSCF + LSFD, `analyze modes`) from a recorded run excited by a '
               f'{cfg.damping_band[0]:g}-{cfg.damping_band[1]:g} Hz Schroeder multisine, '
               f'{settling_text(cfg)}, then '
               f'{cfg.damping_periods} periods of {cfg.damping_period:g} s averaged. Peaks: '
               'identified and analytic sampled-loop FRF, each maximised at the mode. '
               '`damping.csv` holds every scenario and direction (analytic).'),
        markdown_table(_damping_rows(tables['damping'], cfg), COLUMNS['damping']),
        _prose('Stability diagram and identified FRF of the damping run of `tcp_damping` at P2 '
               "(every run's are in the study's `figures/`):"),
        '![stability diagram](figures/stability_P2_tcp_damping.png)\n'
        '![identified FRF](figures/identified_frf_P2_tcp_damping.png)'])


def summary_section(results: Path, cfg: StudyConfig) -> str:
    """The README's sentences on the study's results, made from the CSV copies in ``results``."""
    summary = read_csv(results / 'summary.csv')
    share = {r['position']: r for r in read_csv(results / 'struts12_share.csv')}
    positions, d = list(cfg.positions), cfg.direction
    reduction = {(r['position'], r['scenario']): float(r['peak_reduction']) for r in summary}
    named = [(scn, label) for scn, label in SUMMARY_SCENARIOS
             if all((pos, scn) in reduction for pos in positions)]
    sentences = [
        f'The peak of the TCP {d}{d} compliance in {cfg.band[0]:g}-{cfg.f_max:g} Hz falls, '
        f'baseline over damped at {" / ".join(positions)}, '
        + ', '.join(f'{" / ".join(format(reduction[(pos, scn)], ".3g") for pos in positions)}-'
                    f'fold with the {label}' for scn, label in named)
        + ' (the dampers as the scenarios ship them).']
    by = {m: [float(share[pos][f'{m}_share']) for pos in positions] for m in ('peak', 'rms')}
    verdict = ', '.join(
        f'by {name} {_where([p for p, v in zip(positions, by[m]) if v >= PAPER_SHARE], positions)}'
        for m, name in (('peak', 'peak'), ('rms', 'RMS')))
    sentences.append(
        'With these strut dampers, struts 1 and 2 alone give ' + ' and '.join(
            f'{v:.0%} ({p})' for p, v in zip(positions, by['peak']))
        + ' of the peak improvement of damping all five struts, and '
        + ' and '.join(f'{v:.0%}' for v in by['rms']) + ' of the RMS improvement: the '
        f'paper\'s "at least {PAPER_SHARE:.0%}" holds {verdict}.')
    stable = sum(r['sampled_loop'] == 'stable' for r in summary)
    sentences.append(
        (f'All {stable}' if stable == len(summary) else f'{stable} of the {len(summary)}')
        + ' sampled loops '
        'pass the truncation check (stable with every FE mode up to the check frequency, not '
        'only with the modes the plant keeps).')
    if _has_testbed_runs(summary):
        dev = [float(r['deviation_db']) for r in summary]
        sentences.append(
            'The FRFs measured from the recorded multisine runs (started at the periodic '
            'steady state of the linear loop) differ from the analytic FRFs of the sampled '
            f'loops by at most {max(dev):.2g} dB over every line from {cfg.band[0]:g} to '
            f'{cfg.band[1]:g} Hz.')
    sentences += claim_sentences(results, positions)
    return _prose(f'(generated by `{COMMAND}` from `docs/results/*.csv`) ' + ' '.join(sentences)
                  + ' Tables, figures and what each verdict rests on: '
                  '[docs/results.md](docs/results.md).')


def _strut_laws_part(results: Path, rows: list[dict[str, str]] | None) -> list[str]:
    """The damper table's strut laws on the study's plant (prose and table), if run."""
    if rows is None:
        return []
    return [
        _prose("The strut laws of the damper table ([dampers.md](dampers.md#which-damper-to-"
               "build), `docs/results/dampers.csv`) closed on the study's plant (stage "
               "*the damper table's strut laws*): each as its scenario file ships it and, at the "
               'other positions, also with the gains the table tuned there (column *gains tuned '
               "at*); sampled at the scenario's rate with its delay (the table's, not the "
               "study's sample rate), with its own filters; on all five struts and on struts 1 "
               "and 2 only (a law in the feed drives' loops keeps the drives of the other struts"
               '); exact peaks and band RMS, reductions against the machine with locked drives. '
               "The README's sentences on the 70 % claim are made from these rows for the laws "
               "the table's verdict names. The table's own plant adds the struts' axial modes "
               'on their links (710-750 Hz); test/test_strut_laws.py checks these rows against '
               'dampers.csv within what that difference accounts for:'),
        markdown_table(rows, COLUMNS[STRUT_LAWS])]


def _prose(text: str) -> str:
    return textwrap.fill(text, width=95, break_on_hyphens=False, break_long_words=False)


def _has_testbed_runs(summary: list[dict[str, str]]) -> bool:
    """True if the study that wrote ``summary`` ran the testbed (not ``--analytic-only``)."""
    return any(r.get('deviation_db') for r in summary)


def copy_results(study_out: Path, results: Path, figures: Path) -> None:
    """
    Copy a study run's CSV tables to ``results`` and refresh the figures ``figures`` holds.

    The figures of an ``--analytic-only`` run lack the measured FRFs: they are not copied.
    """
    results.mkdir(parents=True, exist_ok=True)
    for name in TABLES:
        if name in OPTIONAL and not (study_out / f'{name}.csv').is_file():
            continue
        shutil.copyfile(study_out / f'{name}.csv', results / f'{name}.csv')
    if not _has_testbed_runs(read_csv(study_out / 'summary.csv')):
        return
    for old in sorted(figures.glob('*.png')):
        new = study_out / 'figures' / old.name
        if new.exists():
            shutil.copyfile(new, old)


def update_docs(readme: Path, results_md: Path, results: Path,
                cfg: StudyConfig | None = None) -> None:
    """Rewrite the study sections of the README and of docs/results.md from ``results``."""
    cfg = cfg or load_study_config()
    results_md.write_text(replace_section(results_md.read_text(), SECTION,
                                          study_section(results, cfg)))
    readme.write_text(replace_section(readme.read_text(), SUMMARY,
                                      summary_section(results, cfg)))
