"""
The summary table: one row per criterion and position, with its threshold and verdict.

Cells show the measured value and, in parentheses, the analytic reference where one exists
(the open-loop plant for the baseline, the sampled loop with a published linear model for a
controller). Verdicts: ``pass``, ``FAIL`` (against the threshold of config/judge.yaml the row
names), ``info`` (no threshold) and ``not judged`` (the value could not be measured).
"""
from __future__ import annotations

from dataclasses import dataclass
import functools
import math
from typing import Callable, Sequence

import numpy as np

from pentapod_damper.judge.battery import Judged, PositionResult
from pentapod_damper.judge.config import JudgeConfig
from pentapod_damper.judge.demand import RunFaults
from pentapod_damper.judge.machining import depth_mm
from pentapod_sim.sim.stability import STABLE, TRUNCATION, UNSTABLE

PASS, FAIL, INFO, UNJUDGED = 'pass', 'FAIL', 'info', 'not judged'


@dataclass(frozen=True)
class Row:
    """One criterion at one position."""

    position: str
    criterion: str
    unit: str
    baseline: str
    controller: str
    reference: str
    threshold: str
    verdict: str


def num(value: float, analytic: float | None = None, fmt: str = '.3g') -> str:
    """``6.06 (6.06)``: a measured value and its analytic reference; '-' for NaN."""
    if value is None or not math.isfinite(value):
        return '-'
    text = format(value, fmt)
    if analytic is not None and math.isfinite(analytic):
        text += f' ({format(analytic, fmt)})'
    return text


def judge(ok: bool | None) -> str:
    """``pass``, ``FAIL`` or ``not judged`` (None)."""
    return UNJUDGED if ok is None else (PASS if ok else FAIL)


def loop_verdict(plant_stable: bool, check_stable: bool | None) -> str:
    """The truncation check's words for two loop verdicts."""
    if not plant_stable:
        return UNSTABLE
    if check_stable is None:
        return 'stable on the plant (no check model)'
    return STABLE if check_stable else TRUNCATION


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 and math.isfinite(a) and math.isfinite(b) else math.nan


class Summary:
    """Builds the rows of one controller (``label``) with a reference column (``ref``)."""

    def __init__(self, cfg: JudgeConfig, label: str, ref: str | None) -> None:
        self.cfg, self.label, self.ref = cfg, label, ref
        self.rows: list[Row] = []

    def _cells(self, res: PositionResult, cell: Callable[[Judged], str]) -> tuple[str, str, str]:
        judged = res.judged
        other = cell(judged[self.ref]) if self.ref in judged else '-'
        return cell(judged['baseline']), cell(judged[self.label]), other

    def add(self, res: PositionResult, criterion: str, unit: str,
            cell: Callable[[Judged], str], threshold: str, verdict: str) -> None:
        """One row; ``cell`` formats a judged column."""
        self.rows.append(Row(res.position.name, criterion, unit, *self._cells(res, cell),
                             threshold, verdict))

    def position(self, res: PositionResult) -> None:
        """Every row of one position."""
        if self.label not in res.judged:
            return
        mine = res.judged[self.label]
        if mine.multisine:
            self._damping(res)
            self._compliance(res)
            self._machining(res)
            self._demand(res, mine)
        self._robustness(res, mine)
        self._faults(res)

    def _damping(self, res: PositionResult) -> None:
        t = self.cfg.thresholds
        base, mine = res.judged['baseline'], res.judged[self.label]
        for d, modes in res.dominant.items():
            gains = [_ratio(mine.measured_poles[d][k].zeta, base.measured_poles[d][k].zeta)
                     for k in range(len(modes))]
            finite = [g for g in gains if math.isfinite(g)]
            k = int(np.nanargmin(gains)) if finite else 0
            mode = modes[k]

            def cell(j: Judged, k: int = k, d: str = d) -> str:
                poles = j.measured_poles.get(d)
                if not poles:
                    return '-'
                ana = j.analytic_poles.get(d)
                text = num(poles[k].zeta, ana[k].zeta if ana else None)
                gain = _ratio(poles[k].zeta, base.measured_poles[d][k].zeta)
                return text if j is base or not math.isfinite(gain) else f'{text}, x{gain:.3g}'
            ok = None if len(finite) < len(gains) else min(finite) >= t.damping_min_gain
            self.add(res, f'damping ratio, TCP {d}{d}: the dominant mode with the lowest gain '
                     f'of {len(modes)} ({mode.label.text()}, {mode.open.freq_hz:.4g} Hz)', '-',
                     cell, f'gain >= {t.damping_min_gain:g} (every mode)', judge(ok))

    def _compliance(self, res: PositionResult) -> None:
        t = self.cfg.thresholds
        base, mine = res.judged['baseline'], res.judged[self.label]
        best = []
        for d in self.cfg.directions:
            for what, limit in (('peak', t.peak_reduction_min), ('rms', t.rms_reduction_min)):
                def value(j: Judged, d: str = d, what: str = what) -> tuple[float, float]:
                    run, ana = j.multisine.get(d), j.analytic.get(d)
                    if run is None:
                        return math.nan, math.nan
                    m = run.peak.value if what == 'peak' else run.rms
                    a = math.nan if ana is None else (ana.peak.value if what == 'peak'
                                                      else ana.rms)
                    return 1e6 * m, 1e6 * a

                def cell(j: Judged, value: Callable[[Judged], tuple[float, float]] = value
                         ) -> str:
                    m, a = value(j)
                    red = _ratio(value(base)[0], m)
                    text = num(m, a)
                    return text if j is base or not math.isfinite(red) else f'{text}, x{red:.3g}'
                red = _ratio(value(base)[0], value(mine)[0])
                if what == 'peak':
                    best.append(red)
                name = 'peak' if what == 'peak' else 'RMS over the lines'
                self.add(res, f'TCP {d}{d} compliance {name} (reduction)', 'um/N', cell,
                         f'reduction >= {limit:g}', judge(None if not math.isfinite(red)
                                                          else red >= limit))
        top = max((b for b in best if math.isfinite(b)), default=math.nan)
        self.rows.append(Row(res.position.name, 'largest peak reduction over the directions',
                             '-', '1', num(top), '-', f'>= {t.best_peak_reduction_min:g}',
                             judge(None if not math.isfinite(top)
                                   else top >= t.best_peak_reduction_min)))

    def _machining(self, res: PositionResult) -> None:
        base = res.judged['baseline'].machining
        mine = res.judged[self.label].machining
        if base is None or mine is None:
            return
        limit = self.cfg.thresholds.stable_depth_gain_min

        def cell(j: Judged) -> str:
            m = j.machining
            if m is None:
                return '-'
            text = num(depth_mm(m.identified), depth_mm(m.analytic))
            gain = _ratio(m.identified.depth, base.identified.depth)
            return text if j.machining is base else f'{text}, x{gain:.3g}'
        gain = _ratio(mine.identified.depth, base.identified.depth)
        self.add(res, f'minimum stable depth of cut, {self.cfg.operation} (gain)', 'mm', cell,
                 f'gain >= {limit:g}', judge(None if not math.isfinite(gain) else gain >= limit))

    def _demand(self, res: PositionResult, mine: Judged) -> None:
        t = self.cfg.thresholds

        def worst(j: Judged, key: str) -> str:
            values = [getattr(p, key) for p in j.demand]
            values = [v for v in values if math.isfinite(v)]
            return num(max(values)) if values else '-'
        for key, text, unit in (('force_rms_per_n', 'largest effort RMS per N RMS of '
                                 'excitation', 'N/N'),
                                ('force_peak_per_n', 'largest effort peak per N peak of '
                                 'excitation', 'N/N'),
                                ('power_per_n2', 'largest mean absorbed power per N^2 of RMS '
                                 'excitation', 'W/N^2'),
                                ('stroke_per_n', 'largest PMA stroke per N peak of excitation',
                                 'm/N')):
            if key == 'stroke_per_n' and not any(math.isfinite(p.stroke_per_n)
                                                 for p in mine.demand):
                continue
            self.add(res, text, unit, functools.partial(worst, key=key), '-', INFO)
        share = max((p.share_at_limit for p in mine.demand), default=math.nan)
        self.add(res, f'share of the steps at the force limit ({t.force_limit:g}, multisine of '
                 f'{self.cfg.multisine.amplitude:g} N peak)', '-',
                 lambda j: worst(j, 'share_at_limit'), f'<= {t.force_limit_share_max:g}',
                 judge(None if not math.isfinite(share) else share <= t.force_limit_share_max))

    def _robustness(self, res: PositionResult, mine: Judged) -> None:
        t, rob = self.cfg.thresholds, mine.robustness
        if rob is None:
            return
        check = res.position.check
        where = (f'check model ({check.n_modes} modes below '
                 f'{check.meta.get("check_f_max_hz", max(check.frequencies_hz)):.0f} Hz)'
                 if check is not None else 'plant only (no check model)')

        def verdict(j: Judged, delay: int, exact: bool = False) -> str:
            r = j.robustness
            if r is None:
                return '-'
            if exact:
                if not r.exact:
                    return '-'
                e = r.exact[('check' if ('check', delay) in r.exact else 'plant', delay)]
                text = e.verdict
                return f'{text} (radius {e.plant_radius:.6g} / {e.check_radius:.6g})'
            p = r.black_box[('plant', delay)]
            c = r.black_box.get(('check', delay))
            if not p.resolved or (c is not None and not c.resolved):
                return 'not resolved'
            return loop_verdict(p.unstable_poles == 0,
                                None if c is None else c.unstable_poles == 0)
        state = verdict(mine, 0)
        self.add(res, f'sampled loop with the identified controller FRF (Nyquist), {where}',
                 '-', lambda j: verdict(j, 0), STABLE,
                 judge(None if state == 'not resolved' else state == STABLE
                       or (check is None and state.startswith('stable'))))
        delayed = verdict(mine, 1)
        self.add(res, 'the same with one more sample of delay', '-', lambda j: verdict(j, 1),
                 STABLE if t.stable_with_delay else '-',
                 judge(None if delayed == 'not resolved' else delayed.startswith('stable'))
                 if t.stable_with_delay else INFO)
        key = ('check', 0) if ('check', 0) in rob.black_box else ('plant', 0)

        def margin(j: Judged) -> str:
            r = j.robustness
            if r is None:
                return '-'
            b = r.black_box[key]
            text = f'{b.margin:.3g} at {b.margin_hz:.4g} Hz'
            if key in r.model_nyquist:
                text += f' (model: {r.model_nyquist[key].margin:.3g})'
            return text
        value = rob.black_box[key].margin
        self.add(res, f'return-difference margin min sigma(I - L), {key[0]}', '-', margin,
                 f'>= {t.margin_min:g}', judge(value >= t.margin_min if
                                                rob.black_box[key].verdict == STABLE else False))
        self.add(res, 'lowest multiple coherence of the identified controller FRF', '-',
                 lambda j: num(j.robustness.coherence_min) if j.robustness else '-',
                 f'>= {t.coherence_min:g}', judge(None if not math.isfinite(rob.coherence_min)
                                                  else rob.coherence_min >= t.coherence_min))
        if rob.exact:
            agree = verdict(mine, 0, True).rsplit(' (radius ', 1)[0] == state
            self.add(res, 'exact check with the published model (spectral radius, plant / '
                     'check model)', '-', lambda j: verdict(j, 0, True), STABLE,
                     judge(verdict(mine, 0, True).startswith(STABLE + ' ')
                           or verdict(mine, 0, True).startswith(STABLE + ' (')))
            self.add(res, 'black box and exact check agree', '-', lambda j: '-',
                     'same verdict', judge(agree))

    def _faults(self, res: PositionResult) -> None:
        t = self.cfg.thresholds

        def total(j: Judged, key: str) -> str:
            return str(sum(getattr(f, key) for f in j.faults)) if j.faults else '-'
        mine = res.judged[self.label].faults
        for key, text, limit in (('rejected', 'answers the plant rejected', t.rejected_max),
                                 ('missing', 'messages missing from the recordings',
                                  t.missing_max),
                                 ('absent_answers', 'steps without an answer', t.missing_max)):
            value = sum(getattr(f, key) for f in mine)
            self.add(res, text, '-', functools.partial(total, key=key), f'<= {limit}',
                     judge(value <= limit))
        self.add(res, 'steps published again (an answer was late)', '-',
                 lambda j: total(j, 'late_steps'), '-', INFO)
        for f in mine:
            if f.error:
                self.add(res, f'run {f.run} ended early at step {f.steps} of {f.planned}: '
                         f'{f.error}', '-', lambda j: '-',
                         'every run ends', FAIL)
        ended = all(_complete(f) for f in mine)
        self.add(res, 'runs that finished every planned step', '-',
                 lambda j: (f'{sum(_complete(f) for f in j.faults)}/{len(j.faults)}'
                            if j.faults else '-'), 'all', judge(ended))


def _complete(f: RunFaults) -> bool:
    return f.state == 'finished' and f.steps == f.planned


def overall(rows: Sequence[Row]) -> str:
    """``pass`` if no row failed and at least one passed; else ``FAIL`` or ``not judged``."""
    verdicts = [r.verdict for r in rows]
    if FAIL in verdicts:
        return FAIL
    return PASS if PASS in verdicts else UNJUDGED
