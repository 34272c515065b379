"""
"Which damper to build": every law of the table at one machine position, measured alike.

The laws of :func:`~pentapod_damper.design.rows.default_rows`, tuned under the machine's
constraints.

:func:`damper_table` takes the position's models (:class:`~pentapod_sim.sim.design_models.
DesignModel`) and returns a :class:`DamperTable`: per law the sensors and actuators it needs,
its gains, the exact TCP peak and band-RMS reduction against the machine without it, the
static TCP compliance ratio, the check model's stability margin (1 - spectral radius) with the
law's delay and with one more sample, the largest actuator force RMS per newton of TCP force,
and the share struts 1+2 alone give of the all-strut improvement (by peak and by RMS). Every
row says whether the law's own dynamics (filters, delay, sampling) are in its numbers: the
paper's ideal damper is the continuous loop, every other row the sampled loop at the table's
rate with the law's low-pass and delay (default one sample). ROS-free.

Units: compliance m/N, forces N/N, frequencies Hz.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import logging
from typing import Callable, Sequence

import numpy as np

from pentapod_damper.design.rows import default_rows, RowSpec
from pentapod_sim.errors import ConfigError, PortError
from pentapod_sim.plant.drives import link_stiffness
from pentapod_sim.plant.frf_peaks import exact_peak, PoleResidueFrf
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.sim.design_models import DesignModel
from pentapod_sim.sim.drives import FeedDrives
from pentapod_sim.sim.loop_frf import band_mean_square, SampledLoop
from pentapod_sim.sim.loop_poles import continuous_loop_system
from pentapod_sim.sim.tuning import Evaluation, Judge, trade_off, tune, TuneSettings

LOG = logging.getLogger(__name__)
#: Values of the fixed 'feed drives alone' row (the IFF parameters are unused at gain 0).
DRIVES_ALONE = {'gain': 0.0, 'omega_ratio': 1.0, 'lowpass_hz': 300.0}


@dataclass(frozen=True)
class DamperRow:
    """One law at one position (see the module docstring; NaN where not applicable)."""

    law: str
    sensors: str
    actuators: str
    gains: dict[str, float]
    dynamics_included: bool
    strut_law: bool
    peak_reduction: float
    rms_reduction: float
    peak_hz: float
    static_ratio: float
    check_margin: float
    check_margin_extra: float
    effort_rms_per_n: float
    share12_peak: float
    share12_rms: float
    feasible: bool
    note: str = ''
    lowband_ratio: float = float('nan')
    uses_drives: bool = False
    #: Largest actuator stroke RMS over the band per N of TCP force (m/N or rad/N, see
    #: :func:`stroke`), and its unit ('' for none, None: not measured, a table of an older run).
    stroke_rms_per_n: float = float('nan')
    stroke_unit: str | None = None
    #: Margins on the full check model when the table's check model is a subset of it
    #: (:mod:`pentapod_damper.design.verify`; NaN: not verified).
    full_check_margin: float = float('nan')
    full_check_margin_extra: float = float('nan')

    @property
    def stable_on_check(self) -> bool:
        """Stable on the check model with the law's delay and with one more sample."""
        return self.check_margin > 0 and self.check_margin_extra > 0


@dataclass(frozen=True)
class DamperTable:
    """The rows of one position, what they rest on, and the trade-off curves."""

    position: str
    machine: str
    settings: TuneSettings
    baseline_peak: float
    baseline_peak_hz: float
    baseline_rms: float
    baseline_static: float
    check_modes: int
    check_f_max_hz: float
    rows: tuple[DamperRow, ...]
    trade_offs: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    energy: dict[str, dict[str, float]] = field(default_factory=dict)
    magnitudes: dict[str, np.ndarray] = field(default_factory=dict)
    #: The full check model of the verified rows (0, NaN: none).
    full_check_modes: int = 0
    full_check_f_max_hz: float = float('nan')

    @property
    def frequencies_hz(self) -> np.ndarray:
        """The frequencies of ``magnitudes`` [Hz]."""
        return frf_grid(self.settings)

    def row(self, law: str) -> DamperRow:
        """The row of ``law`` (KeyError if none)."""
        for row in self.rows:
            if row.law == law:
                return row
        raise KeyError(law)


def _share(base: float, partial: float, full: float) -> float:
    gained = base - full
    return float((base - partial) / gained) if gained > 0 else float('nan')


def _continuous_frf(judge: Judge, values: dict[str, float],
                    struts: Sequence[int]) -> PoleResidueFrf:
    """The TCP FRF of the continuous loop (no sampling, no delay)."""
    s = judge.settings
    out, inp = s.pair
    plant = judge.machine()
    ctrls = []
    for law in judge.family.laws(values, struts, judge.context(0)):
        model = law.continuous()
        ctrls += model if isinstance(model, list) else [model]
    if s.machine == 'drives':
        ctrls = [FeedDrives(judge.model.drives).continuous()] + ctrls
    a, b, c_y = continuous_loop_system(plant, ctrls)
    j, o = plant.input_names.index(inp), plant.output_names.index(out)
    return PoleResidueFrf.from_state_space(a, b[:, j], c_y[o], plant.state_matrices()[3][o, j])


def _continuous_metrics(judge: Judge, values: dict[str, float], struts: Sequence[int]
                        ) -> tuple[float, float, float]:
    """Peak, its frequency and RMS of the TCP FRF of the continuous loop."""
    frf = _continuous_frf(judge, values, struts)
    peak = exact_peak(frf, *judge.settings.band)
    rms = float(np.sqrt(band_mean_square(frf, frf.poles, *judge.settings.band)))
    return peak.value, peak.freq_hz, rms


def frf_grid(settings: TuneSettings, points: int = 4000) -> np.ndarray:
    """The frequencies [Hz] of the table's FRF figure: log-spaced over the band."""
    return np.geomspace(*settings.band, points)


def magnitude(judge: Judge, values: dict[str, float], ideal: bool) -> np.ndarray:
    """|TCP FRF| [m/N] of a row on :func:`frf_grid` (NaN for an unstable loop)."""
    freq = frf_grid(judge.settings)
    if ideal:
        return np.abs(_continuous_frf(judge, values, judge.settings.struts)(freq))
    out, inp = judge.settings.pair
    try:
        loop = SampledLoop(judge.machine(), judge.controllers(values), judge.settings.dt)
    except ConfigError:
        return np.full(freq.size, np.nan)
    if not loop.spectral_radius < 1:
        return np.full(freq.size, np.nan)
    return np.abs(loop.output(out, inp)(freq))


def measure_row(spec: RowSpec, judge: Judge, values: dict[str, float], best: Evaluation,
                base: Evaluation, radii: tuple[float, float] | None,
                say: Callable[[str], None]) -> DamperRow:
    """Measure one row (its check-model margins and the struts 1+2 share)."""
    ideal = spec.kind == 'ideal'
    table_peak, table_rms = base.peak, base.rms
    if judge.model.check is None:
        radii = (np.nan, np.nan)
    elif radii is None or not np.all(np.isfinite(radii)):
        radii = judge.check(values)
    peak, peak_hz, rms = best.peak, best.peak_hz, best.rms
    share_peak = share_rms = float('nan')
    if ideal:
        peak, peak_hz, rms = _continuous_metrics(judge, values, judge.settings.struts)
    if spec.strut_law:
        partial = judge.evaluate(values, struts=(1, 2), robust=False)
        p12, r12 = partial.peak, partial.rms
        if ideal:
            p12, _, r12 = _continuous_metrics(judge, values, (1, 2))
        share_peak = _share(base.peak, p12, peak)
        share_rms = _share(base.rms, r12, rms)
    say(f'{judge.model.position}: {spec.name}: peak /{table_peak / peak:.2f}, check radius '
        f'{radii[0]:.6f} / {radii[1]:.6f}')
    return DamperRow(spec.name, spec.family.sensors, spec.family.actuators,
                     {k: float(v) for k, v in values.items()}, not ideal, spec.strut_law,
                     table_peak / peak, table_rms / rms, peak_hz, best.static_ratio,
                     1.0 - radii[0], 1.0 - radii[1], best.effort_rms, share_peak, share_rms,
                     best.feasible, spec.note)


def damper_table(model: DesignModel, settings: TuneSettings = TuneSettings(),
                 rows: Sequence[RowSpec] | None = None,
                 progress: Callable[[str], None] | None = None) -> DamperTable:
    """
    The "which damper to build" table of one position.

    Parameters
    ----------
    model : DesignModel
        The position's design plant, check model, stiffness corners and drives
        (:func:`pentapod_sim.sim.design_models.load_design_model`).
    settings : TuneSettings
        Sample rate, TCP direction, objective and constraints; ``machine`` 'locked' (the FE
        model, as the study) or 'drives' (every row on the machine with its feed drives).
    rows : sequence of RowSpec, optional
        Default :func:`~pentapod_damper.design.rows.default_rows`.
    progress : callable, optional
        Receives one line per stage.
    """
    say = progress or (lambda msg: LOG.info('%s', msg))
    rows = default_rows() if rows is None else rows
    reference = Judge(model, rows[0].family, replace(settings, refine_iterations=0))
    base = reference.baseline
    out_rows, curves, magnitudes = [], {}, {'baseline': magnitude(reference, {}, False)}
    radii = None
    for spec in rows:
        judge = Judge(model, spec.family, settings)
        if spec.kind == 'tuned' and spec.name.startswith('feed drives'):
            values = dict(DRIVES_ALONE)
            best = judge.evaluate(values)
        elif spec.kind == 'tuned':
            result = tune(judge, say)
            curves[spec.name] = [(s, base.peak / (result.baseline.peak / r))
                                 for s, r, _ in trade_off(result)]
            radii = result.check_radius
            best = result.best or _closest(result.evaluations)
            if result.best is None:
                say(f'{model.position}: {spec.name}: no feasible design; the row shows the '
                    'robustly stable one with the least static compliance')
            values = best.values
        else:
            values = {}
            best = judge.evaluate(values)
        base_eval = Evaluation({}, peak=base.peak, rms=base.rms)
        magnitudes[spec.name] = magnitude(judge, values, spec.kind == 'ideal')
        row = measure_row(spec, judge, values, best, base_eval, radii, say)
        out_rows.append(replace(row, lowband_ratio=_lowband(magnitudes, spec.name,
                                                           base.peak_hz, settings),
                                uses_drives=spec.family.machine == 'drives'))
        value, unit = stroke(judge, values)
        out_rows[-1] = replace(out_rows[-1], stroke_rms_per_n=value, stroke_unit=unit)
        radii = None
    check = model.check
    return DamperTable(model.position, reference.settings.machine, settings, base.peak,
                       base.peak_hz, base.rms, base.static,
                       check.n_modes if check is not None else 0,
                       float(check.meta.get('check_f_max_hz', np.nan)) if check is not None
                       else float('nan'), tuple(out_rows), curves, _energy(model, settings),
                       magnitudes)


def _lowband(magnitudes: dict[str, np.ndarray], name: str, peak_hz: float,
             settings: TuneSettings) -> float:
    """
    Largest ratio of a row's |TCP FRF| to the baseline's below half the baseline's peak.

    The static limit binds at 0 Hz only; a law with a position loop around it (HAC-LAC) or
    the drives' own servo compliance may still soften the machine in this band.
    """
    freq = frf_grid(settings)
    band = freq <= 0.5 * peak_hz
    ratio = magnitudes[name][band] / magnitudes['baseline'][band]
    # NaN for an unstable loop (its magnitudes are NaN) or an empty band
    return float(np.max(ratio)) if ratio.size else float('nan')


def _closest(evaluations: Sequence[Evaluation]) -> Evaluation:
    """The robustly stable design with the least static compliance (best peak on a tie)."""
    stable = [e for e in evaluations if e.radius < 1 and e.radius_extra < 1
              and not e.corner_radius >= 1 and np.isfinite(e.peak)]
    pool = stable or [e for e in evaluations if np.isfinite(e.peak)] or list(evaluations)
    return min(pool, key=lambda e: (round(e.static_ratio, 6) if np.isfinite(e.static_ratio)
                                    else np.inf, e.peak if np.isfinite(e.peak) else np.inf))


def _energy(model: DesignModel, settings: TuneSettings) -> dict[str, dict[str, float]]:
    """
    Strain-energy shares (per stiffness group) of the modes that dominate the TCP.

    The three modes with the largest open-loop peak terms ``|c b| / (2 zeta omega^2)`` in
    the TCP FRF of the table's direction.
    """
    plant, kept = model.plant, model.plant.meta.get('kept_modes')
    if not model.energy or kept is None:
        return {}
    out, inp = settings.pair
    o, j = plant.output_names.index(out), plant.input_names.index(inp)
    terms = np.abs(plant.c_disp[o] * plant.b[:, j]) / (2 * plant.zeta * plant.omega ** 2)
    shares = {}
    for i in np.argsort(-terms)[:3]:
        mode = int(kept[i]) - 1
        shares[f'mode {mode + 1}, {model.energy_freq_hz[mode]:.1f} Hz'] = {
            g: float(v[mode]) for g, v in model.energy.items()}
    return shares


def stroke(judge: Judge, values: dict[str, float]) -> tuple[float, str]:
    """
    The largest actuator stroke of a design: RMS over the band per newton of TCP force.

    A force actuator in series with the nut (``strut<i>_drive_force``: IFF's piezo) extends
    by ``u / k_a`` (the load cell force is ``k_a`` times extension minus link deformation),
    so its stroke is its force over the link stiffness [m/N]; an actuator in parallel with
    the structure (moment pair, chord force, TCP damper) strokes by its port's collocated
    displacement [rad/N for the moment pairs, m/N otherwise]. Measured on the design plant's
    sampled loop (the ideal row too); NaN where the port has no collocated displacement (the
    PMA's proof mass, the drives' motors: HAC-LAC's and the drives' actuator is the motor,
    whose travel is the strut's positioning itself). Returns the stroke and its unit
    ('m/N', 'rad/N', '' for none).
    """
    s, plant = judge.settings, judge.machine()
    out, inp = s.pair
    ctrls = judge.controllers(values)
    try:
        loop = SampledLoop(plant, ctrls, s.dt)
    except ConfigError:
        return float('nan'), ''
    worst, unit = float('nan'), ''
    for port in dict.fromkeys(p for c in ctrls for p in c.actuator_ports):
        if port.endswith('_drive_force') and port.startswith('strut'):
            k_a = link_stiffness(judge.model.plant, int(port[5]))
            value, kind = loop.effort(port, inp).rms(*s.band) / k_a, 'm'
        else:
            try:
                sensor = collocated_output(port, 'displacement')
            except PortError:
                continue
            if sensor not in plant.output_names:
                continue
            value = loop.output(sensor, inp).rms(*s.band)
            kind = 'rad' if 'moment' in port else 'm'
        if not value <= worst:
            worst, unit = value, kind
    return worst, (f'{unit}/N' if unit else '')


def with_lowband(table: DamperTable) -> DamperTable:
    """``table`` with every row's low-band ratio recomputed from its stored magnitudes."""
    return replace(table, rows=tuple(
        replace(row, lowband_ratio=_lowband(table.magnitudes, row.law, table.baseline_peak_hz,
                                            table.settings))
        for row in table.rows))


def add_strokes(table: DamperTable, model: DesignModel, rows: Sequence[RowSpec] | None = None
                ) -> DamperTable:
    """``table`` with the strokes of rows that have none (tables of an older run)."""
    specs = {spec.name: spec for spec in (default_rows() if rows is None else rows)}
    out = []
    for row in table.rows:
        if row.stroke_unit is not None or row.law not in specs:
            out.append(row)
            continue
        judge = Judge(model, specs[row.law].family,
                      replace(table.settings, refine_iterations=0))
        value, unit = stroke(judge, dict(row.gains))
        out.append(replace(row, stroke_rms_per_n=value, stroke_unit=unit))
    return replace(table, rows=tuple(out))
