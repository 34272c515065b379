"""
The study's machining section: stability lobes of every scenario and recorded cuts.

Per (position, scenario) the zero-order lobes of the sampled loop with the scenario's laws as
the study runs them (:func:`pentapod_sim.machining.loop_lobes.loop_lobes`, at the study's
sample rate); per position the lobe diagram of every operation (one curve per scenario); for
the scenarios of ``machining.cutting_runs`` two cuts on the testbed at the lobe bottom whose
runs are shortest, at 0.8x and 1.2x of the predicted limit, each judged from its bag as
``analyze chatter`` judges it (:func:`pentapod_sim.scenario.cutting.record_cut`).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.records import (
    CuttingCheck,
    Figures,
    FloatArray,
    PositionModel,
    Row,
    ScenarioAnalytic,
    Table,
)
from pentapod_damper.study.runs import WARM
from pentapod_sim.machining.lobe_plot import lobe_diagram
from pentapod_sim.machining.loop_lobes import check_runs, loop_lobes, LoopLobes
from pentapod_sim.machining.materials import load_machining, MachiningTable
from pentapod_sim.scenario.cutting import record_cut
from pentapod_sim.scenario.files import read_scenario, Scenario

#: Spindle speeds of a diagram (over the machining table's range).
N_SPEEDS = 2000


def scenario_lobes(cfg: StudyConfig, model: PositionModel,
                   analytic: ScenarioAnalytic) -> LoopLobes:
    """The lobes of one scenario's sampled loop, for every operation of the study."""
    table = load_machining()
    return loop_lobes(model.plant, analytic.laws, cfg.dt, table, cfg.machining_operations,
                      _speeds(table), analytic.name, model.position)


def _speeds(table: MachiningTable) -> FloatArray:
    """The spindle speeds of every diagram [rpm]."""
    low, high = table.spindle_speeds
    return np.linspace(low, high, N_SPEEDS)


def lobe_figures(cfg: StudyConfig, out_dir: Path, position: str,
                 lobes: dict[str, LoopLobes]) -> Figures:
    """The lobe diagram of every operation at one position (PNG and CSV)."""
    speeds = _speeds(load_machining())
    paths = {}
    for op in cfg.machining_operations:
        diagram = lobe_diagram([rec.operations[op].limit for rec in lobes.values()], speeds,
                               out_dir / 'figures' / f'lobes_{position}_{op}',
                               title=f'{position}, {op}: sampled loop at '
                                     f"{cfg.sample_rate:g} Hz with each scenario's laws "
                                     '(stable below)')
        paths[f'Stability lobes at {position}, {op}'] = diagram.png
    return Figures(f'lobes {position}', paths)


def study_cut_scenario(scenario: str, cfg: StudyConfig) -> Scenario:
    """The scenario with every node at the study's sample rate and no start-up loop check."""
    run = read_scenario(scenario)
    for node in run.nodes:
        changes: dict[str, Any] = {}
        if hasattr(node.params, 'sample_rate'):
            changes['sample_rate'] = cfg.sample_rate
        if node is run.plant:
            changes['loop_check'] = 'off'     # the study checks its loops itself
        if changes:
            run = run.with_params(node.name, **changes)
    return run


def cutting_check(cfg: StudyConfig, out_dir: Path, model: PositionModel,
                  analytic: ScenarioAnalytic, lobes: LoopLobes) -> CuttingCheck:
    """Cuts at 0.8x and 1.2x of the predicted limit, recorded and judged."""
    table = load_machining()
    op = cfg.machining_operations[0]
    # three Floquet candidates, as `statespace lobes --check` (a monodromy matrix per run costs
    # about a second on the machine's loop): with one, P2's TCP damper was cut at 833 rpm,
    # where 1.2x grows at only +0.12 1/s by Floquet (a 22 s run; the tool leaving the cut
    # slowed it further and it read stable); with three, at 375 rpm, +1.41 1/s and 2.8 s
    point = check_runs(model.plant, analytic.laws, cfg.dt, table, lobes.operations[op])
    base = study_cut_scenario(analytic.name, cfg)
    cuts = []
    for run in point.runs:
        bag = out_dir / 'runs' / f'{model.position}_{analytic.name}_cut_{run.factor:g}x'
        cuts.append(record_cut(base, run, bag.with_name(bag.name.replace('.', '_')),
                               model_file=str(model.model_file), position=model.position,
                               warm=WARM))
    return CuttingCheck(model.position, analytic.name, op, point.speed, point.depth,
                        point.chatter_freq, cuts)


def lobes_table(cfg: StudyConfig, lobes: dict[tuple[str, str], LoopLobes]) -> Table:
    """Minimum stable depth per operation and its gain over the baseline."""
    rows: list[Row] = []
    for (pos, scn), rec in lobes.items():
        base = lobes[pos, 'baseline']
        row: Row = {'position': pos, 'scenario': scn}
        for op in cfg.machining_operations:
            summ = rec.operations[op].summary
            row[f'{op}_min_depth_mm'] = summ.min_depth * 1e3
            row[f'{op}_chatter_hz'] = summ.min_depth_freq
            row[f'{op}_best_pocket_mm'] = summ.pocket_depth * 1e3
            row[f'{op}_best_pocket_rpm'] = summ.pocket_speed
            row[f'{op}_stable_depth_gain'] = rec.gain_over(base, op)
        rows.append(row)
    text = ("Zero-order (Altintas-Budak) lobes of the sampled loop with each scenario's laws at "
            f'{cfg.sample_rate:g} Hz, over the spindle speeds of config/machining.yaml; the '
            'minimum is over all speeds, the gain is over the baseline at the same position. '
            "The plant's modes only (tool and spindle rigid), the tooth period as the delay, "
            'no process damping (docs/machining.md).')
    return Table('machining', 'Minimum stable depth of cut per scenario', text, rows)


def cuts_table(checks: list[CuttingCheck]) -> Table:
    """The recorded cuts: predicted limit, depth, verdict from the bag."""
    rows: list[Row] = []
    for c in checks:
        for cut in c.cuts:
            v = cut.verdict
            rows.append({'position': c.position, 'scenario': c.scenario,
                         'operation': c.operation, 'speed_rpm': c.speed,
                         'limit_mm': c.depth * 1e3, 'predicted_chatter_hz': c.chatter_freq,
                         'factor': cut.run.factor,
                         'depth_mm': cut.run.params['axial_depth'] * 1e3,
                         'simulated_s': cut.run.duration, 'expected': cut.run.expected,
                         'verdict': v.verdict,
                         'chatter_hz': None if math.isnan(v.chatter_freq) else v.chatter_freq,
                         'growth_per_s': v.growth_rate,
                         'predicted_growth_per_s': cut.run.growth_rate,
                         'averaged_loop_growth_per_s': cut.run.averaged_rate,
                         'off_harmonic_share': v.off_harmonic_share,
                         'as_predicted': cut.as_expected, 'wall_s': cut.wall_time})
    text = ('Cuts with the cutting node on the testbed (composed, recorded), at the lobe bottom '
            'whose runs are shortest (moved to a whole number of steps per tooth period), 0.8x '
            'and 1.2x of the predicted limiting depth; each lasts three e-foldings of the growth '
            '(two of the decay) from the critical Floquet multiplier of the sampled loop with the '
            'time-varying cut (predicted_growth_per_s; the averaged loop, which the zero-order '
            'limit rests on, beside it) plus a quarter for the entry, which the verdict leaves '
            'out.')
    return Table('cutting_runs', 'Recorded cuts against the predicted stability limit', text,
                 rows)
