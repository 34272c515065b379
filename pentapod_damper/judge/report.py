"""
One page per judged controller.

The summary table first, then every section with its tables and figures; written as
``report.md`` (with PNG files in ``figures/``), a self-contained ``report.html`` and
``numbers.csv`` (every number of every table).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from pentapod_damper.judge import figures, tables
from pentapod_damper.judge.battery import PositionResult
from pentapod_damper.judge.config import JudgeConfig
from pentapod_damper.judge.controller import Controller
from pentapod_damper.judge.document import (
    Block,
    Column,
    CSV_HEADER,
    csv_text,
    Figure,
    Heading,
    html_page,
    markdown,
    Paragraph,
    Table,
)
from pentapod_damper.judge.verdict import overall, Row, Summary
from pentapod_sim.machining.lobe_plot import lobe_diagram
from pentapod_sim.machining.materials import load_machining

ASSUMED = ', assumed: the velocities collocated with its ports'
BUILDABLE = ('The controller as published, measured as every law of the buildable-damper '
             'table (docs/dampers.md, the same code): exact TCP peak and band-RMS reduction of '
             'the sampled loop, static TCP compliance over the baseline, check-model margin '
             '(1 - spectral radius) as published and with one more sample of delay, largest '
             'actuator force and stroke RMS per newton of TCP force. Left out: the stiffness '
             "corners and the feed drives' loops; a controller without a published model "
             '(its FRF known on the bins only).')


def _how(ctrl: Controller) -> str:
    how = {'class': 'a node class, run composed with the plant',
           'scenario': 'the force sources of a scenario, run composed with the plant',
           'command': 'a command line started for every run (separate processes)',
           'node': 'a node already running (separate processes)'}[ctrl.how]
    return (f'`{ctrl.label}`: {how}; answers on '
            f'{", ".join(f"/pentapod/forces/{s}" for s in ctrl.sources)}')


def intro(cfg: JudgeConfig, ctrl: Controller, ref: str | None,
          results: Sequence[PositionResult], verdict: str) -> list[Block]:
    """The page's heading and what the verdict rests on."""
    first = results[0]
    mine = first.judged[ctrl.label]
    rob = mine.robustness
    check = first.position.check
    text = (f'Judged: {_how(ctrl)}. Against the baseline (the machine without added damping)'
            f'{f" and `{ref}`" if ref else ""}, at {", ".join(r.position.name for r in results)}'
            f', {cfg.sample_rate:g} Hz lockstep (the controller answers u_k to y_k). Overall: '
            f'**{verdict}**.')
    rests = [f'Every number comes from the recorded runs (the bags are listed under each '
             f'position); the analytic reference, in parentheses, exists for the baseline (the '
             f'open-loop plant) and for a controller that published its linear model'
             f'{" (this one did)" if mine.has_model else " (this one did not)"}. '
             f'Compliance and damping: Schroeder multisine {cfg.multisine.band[0]:g}-'
             f'{cfg.multisine.band[1]:g} Hz, {cfg.multisine.amplitude:g} N peak, lines '
             f'{1 / cfg.multisine.period:g} Hz apart, settled {first.settle_periods} periods of '
             f'{cfg.multisine.period:g} s, {cfg.multisine.periods} averaged; modes identified '
             "by pLSCF + LSFD. The damping compares the baseline's "
             f'{cfg.identification.modes} dominant modes per direction (FE mode number, plant '
             'index and cause).']
    if rob is not None:
        sensors = ', '.join(rob.sensors)
        rests.append(
            f"Loop check: the controller's FRF u / y identified from a run with white noise "
            f'on {", ".join(rob.ports)} (sensors {sensors}'
            f'{ASSUMED if rob.sensors_assumed else ""}'
            f'), closed with the reduced plant ({first.position.plant.n_modes} modes) and '
            + (f'the check model ({check.n_modes} FE modes below '
               f'{check.meta.get("check_f_max_hz", 0):.0f} Hz)' if check is not None
               else 'no check model (a model file without one: the truncated modes are not '
               'checked)')
            + "; the open loop is taken as stable (the plant is; a black box's own poles "
            'cannot be seen from its FRF).')
    return [Heading(f'Judgement of {ctrl.label}', 1), Paragraph(text),
            Paragraph(' '.join(rests))]


def summary_table(rows: list[Row], ctrl: str, ref: str | None) -> Table:
    """The summary: criterion, baseline, controller, reference, threshold, verdict."""
    table = Table('summary', [Column('position'), Column('criterion'), Column('unit'),
                              Column('baseline'), Column(ctrl),
                              Column(ref or 'reference law'), Column('threshold'),
                              Column('verdict')])
    for r in rows:
        table.add(r.position, r.criterion, r.unit, r.baseline, r.controller, r.reference,
                  r.threshold, r.verdict)
    return table


def position_blocks(res: PositionResult, labels: list[str], cfg: JudgeConfig,
                    folder: Path) -> list[Block]:
    """The sections of one position."""
    name = res.position.name
    out: list[Block] = [Heading(f'{name}', 2)]
    mine = res.judged[labels[1]]
    if mine.multisine:
        out += [Heading('Damping per mode', 3), tables.damping_table(res, labels),
                Heading('TCP compliance', 3), tables.compliance_table(res, labels),
                Figure(figures.compliance(res, labels, folder / f'compliance_{name}.png'),
                       f'{name}: TCP compliance per direction')]
        machining = tables.machining_table(res, labels)
        if machining is not None:
            depths = [res.judged[lb].machining for lb in labels if lb in res.judged]
            limits = [d.limit for d in depths if d is not None]
            table = load_machining()
            low, high = table.spindle_speeds
            diagram = lobe_diagram(limits, np.linspace(low, high, 2000),
                                   folder / f'lobes_{name}', title=f'{name}: {cfg.operation}, '
                                   'identified TCP FRF')
            out += [Heading('Machining', 3), machining,
                    Figure(diagram.png, f'{name}: stability lobes from the identified FRFs')]
        out += [Heading('Actuator demand', 3), tables.demand_table(res, labels)]
    buildable = tables.buildable_table(res, labels)
    if buildable is not None:
        out += [Heading('As a buildable damper', 3), Paragraph(BUILDABLE), buildable]
    if mine.robustness is not None:
        out += [Heading('Robustness of the loop', 3), tables.robustness_table(res, labels)]
        for label in labels[1:]:
            j = res.judged.get(label)
            if j is None or j.robustness is None:
                continue
            slug = j.controller.slug
            path = figures.controller(j, cfg.dt, folder / f'controller_{slug}_{name}.png')
            if path is not None:
                out.append(Figure(path, f'{name}: {label} identified in the loop'))
            path = figures.margins(j, folder / f'margins_{slug}_{name}.png')
            if path is not None:
                out.append(Figure(path, f'{name}: {label}, return difference'))
    out += [Heading('Runs, stops and faults', 3), tables.runs_table(res, labels),
            Paragraph('Bags: ' + '; '.join(f'`{r.bag}`' for lb in labels if lb in res.judged
                                             for r in res.judged[lb].records))]
    return out


def write_page(cfg: JudgeConfig, ctrl: Controller, ref: str | None,
               results: Sequence[PositionResult], folder: Path) -> tuple[Path, str, list[Row]]:
    """Write one controller's page; return the Markdown path, the verdict and the rows."""
    folder.mkdir(parents=True, exist_ok=True)
    summary = Summary(cfg, ctrl.label, ref)
    for res in results:
        summary.position(res)
    verdict = overall(summary.rows)
    labels = ['baseline', ctrl.label] + ([ref] if ref else [])
    blocks: list[Block] = intro(cfg, ctrl, ref, results, verdict)
    blocks += [Heading('Summary', 2), summary_table(summary.rows, ctrl.label, ref),
               Paragraph('Cells: the value measured from the recordings, the analytic '
                         'reference in parentheses where one exists, and the gain or '
                         'reduction over the baseline after "x". Thresholds: config/judge.yaml '
                         '(thresholds).')]
    for res in results:
        blocks += position_blocks(res, labels, cfg, folder / 'figures')
    md = folder / 'report.md'
    md.write_text(markdown(blocks, folder), encoding='utf-8')
    (folder / 'report.html').write_text(html_page(blocks, f'Judgement of {ctrl.label}'),
                                        encoding='utf-8')
    (folder / 'numbers.csv').write_text(','.join(CSV_HEADER) + '\n' + csv_text(blocks),
                                        encoding='utf-8')
    return md, verdict, summary.rows
