"""
The report's detail tables of one position: every number measured, beside its reference.

Columns hold numbers (the CSV keeps them at full precision); ``labels`` are the judged columns
in order (the baseline first).
"""
from __future__ import annotations

import math
from typing import Sequence

from pentapod_damper.judge.battery import PositionResult
from pentapod_damper.judge.document import Column, Table
from pentapod_damper.judge.machining import depth_mm


def damping_table(res: PositionResult, labels: Sequence[str]) -> Table:
    """Dominant modes per direction: open loop, then measured and analytic per column."""
    cols = [Column('mode'), Column('direction'), Column('f open', 'Hz', '.4g'),
            Column('zeta open', '-', '.3g')]
    for label in labels:
        cols += [Column(f'f {label}', 'Hz', '.4g'), Column(f'zeta {label}', '-', '.3g'),
                 Column(f'zeta {label}, analytic', '-', '.3g')]
    table = Table(f'{res.position.name} damping per mode', cols)
    for d, modes in res.dominant.items():
        for k, mode in enumerate(modes):
            cells: list[float | str | None] = [mode.label.text(), f'{d}{d} #{mode.rank}',
                                               mode.open.freq_hz, mode.open.zeta]
            for label in labels:
                j = res.judged.get(label)
                measured = j.measured_poles.get(d) if j else None
                ana = j.analytic_poles.get(d) if j else None
                cells += [measured[k].freq_hz if measured else None,
                          measured[k].zeta if measured else None,
                          ana[k].zeta if ana else None]
            table.add(*cells)
    return table


def compliance_table(res: PositionResult, labels: Sequence[str]) -> Table:
    """Peak (identified model) and RMS (lines) per direction, measured and analytic."""
    cols = [Column('quantity')]
    for label in labels:
        cols += [Column(label, 'um/N'), Column(f'{label}, analytic', 'um/N')]
        if label != labels[0]:
            cols.append(Column(f'{label}, reduction', '-'))
    table = Table(f'{res.position.name} TCP compliance', cols)
    base = res.judged[labels[0]]
    for d in res.dominant:
        for what in ('peak', 'peak at', 'RMS', 'settling error'):
            cells: list[float | str | None] = [f'{d}{d} {what}' + (' [Hz]' if what == 'peak at'
                                                                   else '')]
            for label in labels:
                j = res.judged.get(label)
                run = j.multisine.get(d) if j else None
                ana = j.analytic.get(d) if j else None
                if run is None:
                    cells += [None, None] + ([None] if label != labels[0] else [])
                    continue
                value, ref = {
                    'peak': (1e6 * run.peak.value, 1e6 * ana.peak.value if ana else None),
                    'peak at': (run.peak.freq_hz, ana.peak.freq_hz if ana else None),
                    'RMS': (1e6 * run.rms, 1e6 * ana.rms if ana else None),
                    'settling error': (run.settled, None)}[what]
                cells += [value, ref]
                if label != labels[0]:
                    b = base.multisine[d]
                    red = {'peak': b.peak.value / run.peak.value, 'RMS': b.rms / run.rms}
                    cells.append(red.get(what))
            table.add(*cells)
    return table


def machining_table(res: PositionResult, labels: Sequence[str]) -> Table | None:
    """Minimum stable depth: identified, on the lines, analytic; gain over the baseline."""
    base = res.judged[labels[0]].machining
    if base is None:
        return None
    table = Table(f'{res.position.name} machining', [
        Column('column'), Column('depth, identified', 'mm', '.4g'),
        Column('chatter at', 'Hz', '.4g'), Column('depth, lines', 'mm', '.4g'),
        Column('lines resolve it'), Column('depth, analytic', 'mm', '.4g'),
        Column('gain over the baseline', '-', '.3g')])
    for label in labels:
        j = res.judged.get(label)
        m = j.machining if j else None
        if m is None:
            continue
        table.add(label, depth_mm(m.identified), m.identified.freq_hz, depth_mm(m.lines),
                  'yes' if m.lines.resolved else 'no', depth_mm(m.analytic),
                  m.identified.depth / base.identified.depth)
    return table


def demand_table(res: PositionResult, labels: Sequence[str]) -> Table:
    """Per controller, direction and port: effort, power, share at the limit, stroke."""
    table = Table(f'{res.position.name} actuator demand', [
        Column('controller, run, port'), Column('effort RMS per N RMS', 'N/N'),
        Column('effort peak per N peak', 'N/N'), Column('absorbed power per N^2', 'W/N^2'),
        Column('share at the force limit', '-'), Column('PMA stroke per N peak', 'm/N')])
    for label in labels[1:]:
        j = res.judged.get(label)
        for p in (j.demand if j else []):
            table.add(f'{label}, {p.direction}, {p.port}', p.force_rms_per_n,
                      p.force_peak_per_n, p.power_per_n2, p.share_at_limit,
                      p.stroke_per_n if math.isfinite(p.stroke_per_n) else None)
    return table


def buildable_table(res: PositionResult, labels: Sequence[str]) -> Table | None:
    """The buildable-damper table's row (docs/dampers.md) of each controller with a model."""
    table = Table(f'{res.position.name} as a buildable damper', [
        Column('controller, direction'), Column('peak reduction', '-', '.3g'),
        Column('RMS reduction', '-', '.3g'), Column('static compliance ratio', '-', '.4g'),
        Column('check margin', '-', '.3g'), Column('check margin, +1 sample', '-', '.3g'),
        Column('force RMS per N', 'N/N', '.3g'), Column('stroke RMS per N', '-', '.3g'),
        Column('stroke unit')])
    for label in labels[1:]:
        j = res.judged.get(label)
        for d, row in (j.buildable.items() if j else ()):
            table.add(f'{label}, {d}{d}', row.peak_reduction, row.rms_reduction,
                      row.static_ratio, row.check_margin, row.check_margin_extra,
                      row.effort_rms_per_n,
                      row.stroke_rms_per_n if row.stroke_unit else None, row.stroke_unit or '-')
    return table if table.rows else None


def robustness_table(res: PositionResult, labels: Sequence[str]) -> Table:
    """Every loop check: identified FRF (Nyquist), model FRF (Nyquist), exact radius."""
    table = Table(f'{res.position.name} loop checks', [
        Column('controller, loop'), Column('identified: verdict'),
        Column('unstable poles', '-', 'd'), Column('margin', '-', '.3g'),
        Column('at', 'Hz', '.4g'), Column('grid points', '-', 'd'),
        Column('model: verdict'), Column('model margin', '-', '.3g'),
        Column('exact spectral radius', '-', '.7g'), Column('exact verdict')])
    for label in labels[1:]:
        j = res.judged.get(label)
        rob = j.robustness if j else None
        if rob is None:
            continue
        for key, check in sorted(rob.black_box.items()):
            name, delay = key
            model = rob.model_nyquist.get(key)
            exact = rob.exact.get(key)
            radius = None if exact is None else (
                exact.check_radius if name == 'check' else exact.plant_radius)
            table.add(f'{label}, {name}{" +1 sample" if delay else ""} ({check.modes} modes)',
                      check.verdict, check.unstable_poles if check.resolved else None,
                      check.margin, check.margin_hz, check.points,
                      model.verdict if model else None, model.margin if model else None,
                      radius, None if exact is None else (
                          'stable' if radius is not None and radius < 1 else 'unstable'))
    return table


def runs_table(res: PositionResult, labels: Sequence[str]) -> Table:
    """Every run: how it ended, what it lost, how long it took."""
    table = Table(f'{res.position.name} runs', [
        Column('run'), Column('end'), Column('steps', '-', 'd'), Column('planned', '-', 'd'),
        Column('rejected', '-', 'd'), Column('missing', '-', 'd'),
        Column('published again', '-', 'd'), Column('answers repeated', '-', 'd'),
        Column('steps without an answer', '-', 'd'), Column('wall time', 's', '.1f'),
        Column('reused')])
    for label in labels:
        j = res.judged.get(label)
        if j is None:
            continue
        for record, f in zip(j.records, j.faults):
            table.add(f.run, f.state, f.steps, f.planned, f.rejected, f.missing, f.late_steps,
                      f.repeated_answers, f.absent_answers, record.wall_time,
                      'yes' if record.reused else 'no')
    return table
