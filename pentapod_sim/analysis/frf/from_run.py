"""
FRFs of a recorded run, with the estimator its stored excitation calls for.

The exciter stores its :class:`~pentapod_sim.sim.excitation.ExcitationSpec` in the bag
(:func:`pentapod_sim.analysis.bag.excitation_record.excitation_of`); :func:`frfs_from_bag` rebuilds
the signal (period, lines, settling, stepped-sine windows) and picks

* periodic kinds (multisine, periodic chirp): synchronous averaging over whole periods after
  the settling periods (:func:`pentapod_sim.analysis.frf.periodic.synchronous_frf`);
* stepped sine: a sine fit per measuring window
  (:func:`pentapod_sim.analysis.frf.stepped_sine.stepped_sine_frf`);
* random, chirp, impulse: H1 (:func:`pentapod_sim.analysis.frf.estimation.estimate_frf`).

Samples are placed on the plant steps ``k = round(t / dt)`` of their header stamps, so the
excitation's step indices (``start_delay`` included) address the recorded arrays directly.
The input is the recorded force projected on the excitation direction [N].
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from pentapod_sim.analysis.bag.excitation_record import excitation_of
from pentapod_sim.analysis.bag.reader import Bag, open_bag, Series
from pentapod_sim.analysis.frf.estimation import estimate_frf
from pentapod_sim.analysis.frf.periodic import LineFrf, synchronous_frf
from pentapod_sim.analysis.frf.stepped_sine import stepped_sine_frf
from pentapod_sim.errors import BagError
from pentapod_sim.interface import EXCITATION, TCP_STATE
from pentapod_sim.sim.excitation import Excitation, PERIODIC_KINDS

#: excitation kinds analysed by H1, with the estimate_frf excitation they map to
H1_KINDS = {'random': 'random', 'chirp': 'chirp', 'impulse': 'impulse'}
#: output unit -> FRF form for LSFD residuals
FRF_FORMS = {'m': 'receptance', 'rad': 'receptance', 'm/s': 'mobility', 'rad/s': 'mobility',
             'm/s^2': 'accelerance', 'rad/s^2': 'accelerance'}


@dataclasses.dataclass
class RunFrfs:
    """
    FRFs of one recorded run, from the excitation to each output.

    Attributes
    ----------
    freq : (F,) ndarray
        Frequencies [Hz] (excited lines for periodic and stepped sine).
    H : (No, 1, F) complex ndarray
        FRFs [output unit / N].
    sigma : (No, 1, F) ndarray or None
        Noise standard deviation per line (periodic, stepped sine), else None.
    transient : (No, 1, F) ndarray or None
        Transient error estimate per line (periodic, stepped sine), else None.
    labels : list of str
        ``TOPIC.FIELD`` per output.
    units : list of str
        Unit of each output's FRF, e.g. ``'m/N'``.
    kind : str
        Excitation kind; ``estimator`` names the estimator used.
    estimator : str
    band : (float, float)
        Band the excitation covers [Hz].
    frf_form : str
        receptance, mobility or accelerance (from the first output's unit).
    n_averages : int
        Periods averaged, shortest stepped-sine window [periods], or Welch segments.
    """

    freq: np.ndarray
    H: np.ndarray
    sigma: Optional[np.ndarray]
    transient: Optional[np.ndarray]
    labels: list[str]
    units: list[str]
    kind: str
    estimator: str
    band: tuple[float, float]
    frf_form: str
    n_averages: int


@dataclasses.dataclass
class _Common:
    labels: list[str]
    units: list[str]
    kind: str
    frf_form: str


def default_outputs(bag: Bag) -> list[str]:
    """The translational TCP displacements ``/pentapod/tcp_state.position.tcp_{x,y,z}``."""
    if TCP_STATE not in bag.topics:
        raise BagError(f'{bag.path} has no {TCP_STATE}; name the outputs (--outputs)')
    found = [f'{TCP_STATE}.{f}' for f in bag.fields(TCP_STATE)
             if f.startswith('position.') and f.rsplit('_', 1)[-1] in ('x', 'y', 'z')]
    if not found:
        raise BagError(f'{TCP_STATE} in {bag.path} has no position.tcp_x/y/z fields; '
                       'name the outputs (--outputs)')
    return found


def _on_steps(series: Series, dt: float) -> tuple[int, np.ndarray]:
    """(first step, values per step) of a series stamped on plant steps; gaps are errors."""
    steps = np.rint(series.time_ns / (dt * 1e9)).astype(np.int64)
    order = np.argsort(steps, kind='stable')
    steps, values = steps[order], np.asarray(series.values, dtype=float)[order]
    keep = np.concatenate([[True], np.diff(steps) > 0])
    steps, values = steps[keep], values[keep]
    gaps = np.flatnonzero(np.diff(steps) != 1)
    if len(gaps):
        raise BagError(f'{series.label}: {len(gaps)} gap(s) in the steps of dt = {dt:g} s '
                       f'(first after step {steps[gaps[0]]}); a lockstep recording has none')
    return int(steps[0]), values


def _common(first_steps: Sequence[int], arrays: Sequence[np.ndarray]
            ) -> tuple[int, list[np.ndarray]]:
    start = max(first_steps)
    end = min(f + len(a) for f, a in zip(first_steps, arrays))
    if end - start < 16:
        raise BagError(f'the input and outputs share only {max(end - start, 0)} steps')
    return start, [a[start - f:end - f] for f, a in zip(first_steps, arrays)]


def frfs_from_bag(bag_path: str | Path, outputs: Optional[Sequence[str]] = None,
                  input_spec: Optional[str] = None, source: Optional[str] = None) -> RunFrfs:
    """
    Estimate the FRFs of a recorded run from its stored excitation to ``outputs``.

    Parameters
    ----------
    bag_path : str or Path
        Bag folder or .mcap file.
    outputs : sequence of str, optional
        ``TOPIC.FIELD`` of the responses; default :func:`default_outputs`.
    input_spec : str, optional
        ``TOPIC.FIELD`` of the input force [N]; default the recorded excitation force
        projected on the excitation direction.
    source : str, optional
        Exciter name, if the bag holds several excitations.

    Returns
    -------
    RunFrfs

    Raises
    ------
    BagError
        If the bag holds no excitation record, its kind gives no FRF over a band (step, sine,
        none), or the series do not cover the excitation.
    """
    found = excitation_of(bag_path, source)
    if found is None:
        raise BagError(f'{bag_path} holds no excitation record (/pentapod/excitation_spec/...);'
                       ' record a run whose exciter stores its signal, or use `analyze frf` '
                       'with --excitation')
    spec, dt = found
    if spec.kind not in PERIODIC_KINDS + ('stepped_sine',) + tuple(H1_KINDS):
        raise BagError(f'excitation kind {spec.kind!r} of {bag_path} excites no band; modal '
                       'identification needs multisine, periodic_chirp, stepped_sine, random, '
                       'chirp or impulse')
    exc = Excitation(spec, dt)
    bag = open_bag(bag_path)
    outputs = list(outputs) if outputs else default_outputs(bag)
    if input_spec:
        u_series = [bag.series(input_spec)]
        weights = [1.0]
    else:
        u_series = [bag.series(f'{EXCITATION}.force.{a}') for a in 'xyz']
        weights = list(exc.direction)
    y_series = [bag.series(spec_) for spec_ in outputs]
    placed = [_on_steps(s, dt) for s in u_series + y_series]
    start, arrays = _common([p[0] for p in placed], [p[1] for p in placed])
    terms = [w * a for w, a in zip(weights, arrays[:len(u_series)])]
    u = sum(terms[1:], terms[0])
    ys = arrays[len(u_series):]
    units = [f'{s.unit}/N' for s in y_series]
    form = FRF_FORMS.get(y_series[0].unit, 'receptance')
    common = _Common(outputs, units, spec.kind, form)
    if spec.kind in PERIODIC_KINDS:
        return _periodic(exc, u, ys, start, dt, common)
    if spec.kind == 'stepped_sine':
        windows = [(f, a - start, b - start) for f, a, b in exc.stepped_windows()]
        lines = exc.lines_hz
        return _line_result([stepped_sine_frf(u, y, dt, windows) for y in ys],
                            'stepped-sine line fit', (lines.min(), lines.max()), common)
    h1 = [estimate_frf(u, y, 1.0 / dt, H1_KINDS[spec.kind]) for y in ys]
    band = (spec.f_start, spec.f_end) if spec.kind != 'impulse' else (0.0, 0.5 / dt)
    return RunFrfs(h1[0].freq, np.array([r.H for r in h1])[:, None, :], None, None,
                   common.labels, common.units, common.kind, 'H1', band, common.frf_form,
                   h1[0].n_averages)


def _periodic(exc: Excitation, u: np.ndarray, ys: list[np.ndarray], start: int, dt: float,
              common: _Common) -> RunFrfs:
    period = int(exc.period_steps or 0)
    first = exc.first + exc.settle_periods * period  # absolute step of the first used period
    if first < start:  # recording began later: skip to the next period boundary
        first += math.ceil((start - first) / period) * period
    end = start + len(u)
    if math.isfinite(exc.spec.duration):
        end = min(end, exc.first + int(round(exc.spec.duration / dt)))
    n_periods = (end - first) // period
    if n_periods < 2:
        raise BagError(f'the record holds {max(n_periods, 0)} whole period(s) of '
                       f'{period * dt:g} s after {exc.settle_periods} settling period(s); '
                       'record longer (at least 2 to average)')
    cut = slice(first - start, first - start + n_periods * period)
    res = [synchronous_frf(u[cut], y[cut], dt, period, 0, exc.lines_hz) for y in ys]
    lines = exc.lines_hz
    return _line_result(res, f'synchronous average of {n_periods} periods',
                        (lines.min(), lines.max()), common)


def _line_result(res: Sequence[LineFrf], estimator: str, band: tuple[float, float],
                 common: _Common) -> RunFrfs:
    return RunFrfs(res[0].freq, np.array([r.H for r in res])[:, None, :],
                   np.array([r.noise_std for r in res])[:, None, :],
                   np.array([r.transient for r in res])[:, None, :], common.labels,
                   common.units, common.kind, estimator, (float(band[0]), float(band[1])),
                   common.frf_form, res[0].n_averages)
