"""
The table's strut laws run on the testbed: their damping identified from recorded runs.

For each position and recorded law, the law's tuned record becomes a scenario file
(:func:`pentapod_damper.design.scenarios.scenario_text`, the gains of that position), which
runs through the study's damping stage: the study's reduced plant of the position, the laws
stepped by the damper node in lockstep at the table's sample rate, a periodic multisine on the
TCP from the loop's periodic steady state (``damping.start``, as the study), recorded, its FRF
identified (pLSCF + LSFD) and each mode that dominates TCP xx paired with the sampled loop's
pole (:mod:`pentapod_damper.study.measured_damping`). The analytic reference is the sampled
loop of the laws' own linear models: the same filters, hold and delay the node runs. ROS
appears only in the run (:func:`pentapod_damper.study.runs.run_on_testbed`).

    python -m pentapod_damper.design --from-tables ... --record out/design/record
        [--record-laws 'lag displacement, bending; IFF'] --docs docs/dampers.md

Units: frequencies [Hz], damping ratios [-], peaks [um/N].
"""
from __future__ import annotations

import csv
from dataclasses import asdict, dataclass
import logging
import math
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from pentapod_damper.design.report import best_strut_law, Record
from pentapod_damper.design.scenarios import node_params, scenario_text, SCENARIOS
from pentapod_damper.study import stages
from pentapod_damper.study.config import load_study_config, StudyConfig
from pentapod_damper.study.measured_damping import IdentifiedMode
from pentapod_damper.study.records import PositionModel
from pentapod_damper.study.runs import RunResult
from pentapod_sim.errors import ConfigError
from pentapod_sim.sim.design_models import load_design_model

LOG = logging.getLogger(__name__)

#: Tolerances of an identified mode against its sampled-loop pole (those of the study's
#: recorded-run test, test/test_study_run.py): damping ratio, frequency (relative) and peak.
ZETA_TOLERANCE = 0.05
FREQ_TOLERANCE = 0.001
PEAK_TOLERANCE_DB = 1.0
#: Laws recorded by default, besides the verdict's law to build.
DEFAULT_LAWS = ('lag displacement, bending', 'IFF')
#: Columns of ``recorded.csv`` (and of the docs block).
COLUMNS = ('position', 'law', 'direction', 'rank', 'mode', 'fe_mode', 'cause',
           'sampled_freq_hz', 'sampled_zeta', 'continuous_zeta', 'measured_freq_hz',
           'measured_zeta', 'zeta_error', 'freq_error', 'peak_analytic_um_per_N',
           'peak_error_db', 'within', 'sample_rate_hz', 'delay_steps', 'settle_s',
           'periods', 'period_s', 'wall_s', 'start')


@dataclass(frozen=True)
class RecordedMode:
    """One mode of a recorded law: the sampled-loop pole and what the run identified of it."""

    position: str
    law: str
    direction: str
    rank: int
    mode: int
    fe_mode: int
    cause: str
    sampled_freq_hz: float
    sampled_zeta: float
    continuous_zeta: float
    measured_freq_hz: float
    measured_zeta: float
    zeta_error: float
    freq_error: float
    peak_analytic_um_per_N: float
    peak_error_db: float
    within: bool
    sample_rate_hz: float
    delay_steps: int
    settle_s: float
    periods: int
    period_s: float
    wall_s: float
    start: str          # 'steady' (the loop's periodic steady state) or 'rest'


def within_tolerances(zeta_error: float, freq_error: float, peak_error_db: float) -> bool:
    """True if an identified mode matches its pole within the tolerances (NaN: unpaired)."""
    return bool(abs(zeta_error) <= ZETA_TOLERANCE and abs(freq_error) <= FREQ_TOLERANCE
                and abs(peak_error_db) <= PEAK_TOLERANCE_DB)


def laws_to_record(records: Sequence[Record], position: str,
                   names: Sequence[str] = DEFAULT_LAWS, build: bool = True) -> list[Record]:
    """
    The locked table's records of ``position`` to record: the law to build (``build``), ``names``.

    Only laws a scenario runs (:data:`pentapod_damper.design.scenarios.SCENARIOS`); the
    drives' rows (HAC-LAC, the drives alone) run on the plant with the drives' rotors (their
    scenarios' plant parameter ``drives``), and their reference is that loop's poles.
    """
    mine = [r for r in records if r['position'] == position and r['machine'] == 'locked']
    best = best_strut_law(mine, low_band=True) if build else None
    wanted = ([best['law']] if best is not None else []) + list(names)
    out: list[Record] = []
    for name in dict.fromkeys(wanted):
        if name not in SCENARIOS:
            raise ConfigError(f'law {name!r} cannot be recorded: no damper node runs it '
                              f'(recordable: {", ".join(SCENARIOS)})')
        rows = [r for r in mine if r['law'] == name]
        if not rows:
            raise ConfigError(f'no record of {name!r} at {position} in the table')
        out += rows
    return out


def record_law(cfg: StudyConfig, model: PositionModel, scenario: Path, out_dir: Path,
               say: Callable[[str], None]
               ) -> tuple[list[IdentifiedMode], dict[str, Any], RunResult]:
    """
    One scenario's damping run at ``model``'s position, compared with the sampled loop.

    The study's damping stage (:func:`pentapod_damper.study.stages.record_damping`): the loop
    checked and its poles computed, the multisine run recorded in lockstep from the loop's
    periodic steady state (or from rest, ``damping.start``), identified, each mode that
    dominates the TCP paired with its pole.
    """
    freq = np.linspace(1.0, cfg.f_max, 400)
    ana = stages.analyse_scenario(cfg, freq, model, str(scenario), damping_run=True)
    if ana.loop is not None:
        say(ana.loop.summary())
    start = 'the periodic steady state' if cfg.damping_start == 'steady' else 'rest'
    say(f'recording {cfg.damping_periods} periods of {cfg.damping_period:g} s at '
        f'{cfg.sample_rate:g} Hz from {start}')
    run, exciter, _, compared = stages.record_damping(cfg, out_dir, model, ana)
    return compared, exciter, run


def record_position(records: Sequence[Record], position: str, out_dir: Path,
                    say: Callable[[str], None], names: Sequence[str] = DEFAULT_LAWS,
                    period: float | None = None, build: bool = True) -> list[RecordedMode]:
    """
    Record the laws of one position and compare their identified damping with the poles.

    The study's settings (config/study.yaml) at each record's sample rate; ``period``
    replaces its multisine period [s] (finer lines: at P2 the two lowest modes lie 0.14 Hz
    apart). ``build``: also the verdict's law to build (:func:`laws_to_record`).
    """
    chosen = laws_to_record(records, position, names, build)
    stiffness = None
    result: list[RecordedMode] = []
    models = {}
    for record in chosen:
        rate = float(record['sample_rate_hz'])
        run_cfg = load_study_config(sample_rate=rate, damping_period=period)
        if rate not in models:
            models[rate] = stages.build_model(run_cfg, out_dir, position)
        model = models[rate]
        if stiffness is None:
            stiffness = load_design_model(position, rate, check=False, corners=False).stiffness
        path = out_dir / 'scenarios' / position / f'{SCENARIOS[record["law"]][0]}.yaml'
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(scenario_text(record, node_params(record, stiffness)))
        compared, exciter, run = record_law(run_cfg, model, path, out_dir,
                                            lambda msg: say(f'{position} {record["law"]}: '
                                                            f'{msg}'))
        for m in compared:
            row = m.analytic
            result.append(RecordedMode(
                position, record['law'], row.direction, row.rank, row.mode, row.fe_mode,
                row.cause, row.sampled_freq_hz, row.sampled_zeta, row.continuous_zeta,
                m.measured_freq_hz, m.measured_zeta, m.zeta_error, m.freq_error,
                m.peak_analytic_um_per_N, m.peak_error_db,
                within_tolerances(m.zeta_error, m.freq_error, m.peak_error_db), rate,
                int(record['delay_steps']), float(exciter['settle_periods'])
                * run_cfg.damping_period, run_cfg.damping_periods, run_cfg.damping_period,
                run.wall_time, run_cfg.damping_start))
            say(f'  mode {row.mode} ({row.sampled_freq_hz:.2f} Hz): zeta sampled loop '
                f'{row.sampled_zeta:.5f}, identified {m.measured_zeta:.5f} '
                f'({m.zeta_error:+.1%}), peak {m.peak_error_db:+.2f} dB')
    return result


def write_csv(rows: Sequence[RecordedMode], path: Path) -> Path:
    """``recorded.csv``: one line per recorded law and mode."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: repr(v) if isinstance(v, float) else v
                             for k, v in asdict(row).items()})
    return path


def read_csv(path: str | Path) -> list[dict[str, str]]:
    """The rows of a ``recorded.csv``."""
    with open(path, newline='') as stream:
        return list(csv.DictReader(stream))


def merge_csv(paths: Sequence[Path], path: Path) -> Path:
    """One ``recorded.csv`` of the rows of several (runs of separate positions)."""
    rows = [row for p in paths for row in read_csv(p)]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    return path


def _pct(text: str) -> str:
    value = float(text)
    return '-' if math.isnan(value) else f'{value:+.1%}'


def _start_text(row: dict[str, str]) -> str:
    """How a recorded run started and settled (rows of files without ``start``: from rest)."""
    settle = float(row['settle_s'])
    if row.get('start') == 'steady':
        return (f"from the loop's periodic steady state under it, {settle:g} s discarded for "
                "the laws' own start")
    return f'from rest, {settle:g} s of settling (decay times of the strongest modes)'


def markdown(rows: Sequence[dict[str, str]]) -> str:
    """The docs block: per position and law, identified against sampled-loop damping."""
    if not rows:
        return '(no recorded runs yet)'
    first = rows[0]
    lines = [
        f'Recorded lockstep runs through the damper node at {float(first["sample_rate_hz"]):g} '
        f'Hz with {first["delay_steps"]} sample(s) of computational delay; the analytic '
        "reference is the sampled loop's poles **with the laws' own dynamics** (their filters, "
        "hold and delay: the linear model of what the node steps) on the plant the scenario's "
        "plant node steps: the study's plant of the position, for the feed drives' rows "
        "(HAC-LAC, the drives alone) with the drives' rotors. Multisine 2-200 Hz on TCP x, "
        f'{_start_text(first)}, then '
        f'{first["periods"]} periods of {float(first["period_s"]):g} s '
        "averaged; pLSCF + LSFD. Tolerances (the recorded-run test's): "
        f'ζ within {ZETA_TOLERANCE:.0%}, f within {FREQ_TOLERANCE:.1%}, peak within '
        f'{PEAK_TOLERANCE_DB:g} dB.', '',
        '| position | law | mode (FE mode, cause) | f sampled [Hz] | ζ sampled loop | '
        'ζ continuous loop | ζ identified | ζ error | f error | peak [µm/N] | '
        'peak error [dB] | within |',
        '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        lines.append(
            f'| {r["position"]} | {r["law"]} | {r["mode"]} ({r["fe_mode"]}, {r["cause"]}) '
            f'| {float(r["sampled_freq_hz"]):.2f} | {float(r["sampled_zeta"]):.4g} '
            f'| {float(r["continuous_zeta"]):.4g} | {float(r["measured_zeta"]):.4g} '
            f'| {_pct(r["zeta_error"])} | {float(r["freq_error"]):+.3%} '
            f'| {float(r["peak_analytic_um_per_N"]):.3g} | {float(r["peak_error_db"]):+.2f} '
            f'| {"yes" if r["within"] == "True" else "**no**"} |')
    return '\n'.join(lines)
