"""
Damping per mode: the analytic sampled-loop poles against the modes identified from a run.

A damping run excites the TCP with a periodic multisine (:func:`runs.damping_excitation`)
for a settling time that follows from the loop's analytic poles
(:func:`pentapod_damper.study.damping.settling_time`), then
for whole periods that the analysis averages synchronously. The bag's FRFs are identified by
pLSCF + LSFD (:mod:`pentapod_sim.analysis.ema.identify`) and each dominant mode of the analytic
table (:mod:`pentapod_damper.study.damping`) is paired with the identified pole nearest in
frequency. Peaks compare the identified model's FRF with the analytic sampled-loop FRF, both
maximised at the resonance (:func:`pentapod_sim.plant.frf_peaks.maximise_near_poles`).
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_damper.study import damping
from pentapod_damper.study.analytic import SampledLoop, SampledPairFrf
from pentapod_damper.study.damping import ModeDamping
from pentapod_sim.analysis.ema import plots as ema_plots
from pentapod_sim.analysis.ema.identify import identify_modes, ModalModel
from pentapod_sim.analysis.ema.poles import Tolerances
from pentapod_sim.analysis.frf.from_run import frfs_from_bag, RunFrfs
from pentapod_sim.errors import BagError
from pentapod_sim.interface import TCP_STATE
from pentapod_sim.plant.drives import DrivenPlant
from pentapod_sim.plant.frf_peaks import maximise_near_poles
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.loop_poles import LoopPoles

#: The identified pole nearest an analytic one in the s-plane is paired with it if their
#: frequencies differ by less than this fraction, or by less than PAIR_BANDWIDTHS analytic
#: half-power bandwidths (2 zeta f).
PAIR_TOLERANCE = 0.005
PAIR_BANDWIDTHS = 1.0
#: Highest pLSCF order: the 2-200 Hz band holds 30-40 modes at P2, and with the default 60
#: orders the automatic selection missed several of them (tcp_damping at P2: 3 modes found).
MAX_ORDER = 120
#: Pole selection of a damping run: every stable mode counts (min_stable_fraction 0: the weakest
#: dominant modes of a loop are stable over fewer orders than the strongest); followed over
#: the orders with one pole of an order per mode (two close modes stay two); noise-free, so a
#: mode's pole from the upper half of its orders, where it has converged (the median over all
#: orders put P2's first mode +1.4 % off under IFF, +3.1 % under band-pass velocity feedback).
TOLERANCES = Tolerances(min_stable_fraction=0.0, one_per_order=True, upper_orders=True)
#: Modes whose decay sets the settling time: the SETTLE_MODES largest pole terms in TCP dd
#: (the three dominant ones alone settled P2 tcp_damping in 1.3 s while 0.1 %-damped modes
#: with smaller terms still rang and biased the damping ratios by 10-20 %).
SETTLE_MODES = 8
#: Half width of the band a peak is searched in, in half-power bandwidths (at least 0.5 Hz).
PEAK_BANDWIDTHS = 5.0


@dataclass
class Identified:
    """The identification of one damping run."""

    run: RunFrfs
    model: ModalModel
    output: str


@dataclass(frozen=True)
class IdentifiedMode:
    """
    A dominant mode of a loop (``analytic``) and what the damping run identified of it.

    ``measured_freq_hz`` and ``measured_zeta`` are NaN if no identified pole pairs with the
    mode; ``freq_error`` and ``zeta_error`` relative to the sampled-loop pole;
    ``peak_analytic_um_per_N``: the sampled-loop FRF maximised near the mode,
    ``peak_measured_um_per_N``: the identified model's FRF maximised near its pole.
    """

    analytic: ModeDamping
    measured_freq_hz: float
    measured_zeta: float
    freq_error: float
    zeta_error: float
    peak_analytic_um_per_N: float
    peak_measured_um_per_N: float
    peak_error_db: float


def identify_run(bag: Path, direction: str, band: Sequence[float]) -> Identified:
    """
    FRF TCP displacement / TCP force along ``direction`` from the bag, and its modes.

    The lines must be closer than the closest pair of modes to be told apart: at P2 the two
    lowest modes lie 0.14 Hz apart (config/study.yaml: ``damping.period`` 8 s, 0.125 Hz).
    Two modes whose half-power bands overlap (P2's feed drives: 0.16 Hz apart, 1.2 and 0.5 Hz
    wide) are told apart by the pole selection, which follows the stability diagram's orders
    with at most one pole of an order per mode (:func:`pentapod_sim.analysis.ema.poles.
    select_poles`). One output, the TCP along ``direction``: the TCP's three outputs resolve
    the same poles, but with their poles the LSFD synthesis of this output, whose peak is
    compared, missed the loop's by up to 1.5 dB (docs/recording.md, step 3).

    Raises
    ------
    BagError
        If the bag lacks the excitation record or the identification finds no mode.
    """
    output = f'{TCP_STATE}.position.tcp_{direction}'
    run = frfs_from_bag(bag, [output])
    try:
        # unweighted: the testbed has no measurement noise, so the scatter of the averaged
        # periods is rounding (about 1e-12 of |H|) and weighting by it would be arbitrary
        # (it moved the damping ratio of the 27 Hz mode by 7-11 % in the study's runs);
        # the pole selection: TOLERANCES
        model = identify_modes(run.freq, run.H, band=tuple(band), sigma=None,
                               frf_form=run.frf_form, orders=range(1, MAX_ORDER + 1),
                               tol=TOLERANCES)
    except ValueError as err:
        raise BagError(f'{bag}: modal identification failed: {err}') from None
    return Identified(run, model, output)


def _pole(f: npt.ArrayLike, zeta: npt.ArrayLike) -> npt.NDArray[np.complex128]:
    w, z = 2 * np.pi * np.asarray(f), np.asarray(zeta)
    return -z * w + 1j * w * np.sqrt(np.clip(1 - z ** 2, 0.0, None))


def _pair(f0: float, zeta0: float, model: ModalModel) -> int | None:
    """Index of the identified pole paired with an analytic one, or None."""
    if not len(model.freq_hz):
        return None
    j = int(np.argmin(np.abs(_pole(model.freq_hz, model.damping) - _pole(f0, zeta0))))
    tol = max(PAIR_TOLERANCE * f0, PAIR_BANDWIDTHS * 2.0 * zeta0 * f0)
    return j if abs(model.freq_hz[j] - f0) <= tol else None


def _local_band(f0: float, zeta: float) -> tuple[float, float]:
    half = max(PEAK_BANDWIDTHS * zeta * f0, 0.5)
    return max(f0 - half, 1e-3), f0 + half


def compare(rows: Sequence[ModeDamping], ident: Identified, plant: PlantModel | DrivenPlant,
            laws: Sequence[Any], dt: float, direction: str,
            loop: SampledLoop | None = None) -> list[IdentifiedMode]:
    """
    The analytic modes of ``direction`` with the identified frequency, damping ratio and peak.

    ``loop``: the sampled loop of the same plant, laws and ``dt``
    (:func:`pentapod_damper.study.analytic.sampled_loop`), if already built.
    """
    model = ident.model
    frf = SampledPairFrf(plant, laws, dt, f'tcp_displacement_{direction}',
                         f'tcp_force_{direction}', loop)
    out = []
    for row in rows:
        if row.direction not in (direction, direction * 2):
            continue
        f0, z0 = row.sampled_freq_hz, row.sampled_zeta
        lo, hi = _local_band(f0, z0)
        analytic = maximise_near_poles(lambda f: np.abs(frf(f)), frf.poles, lo, hi).value
        j = _pair(f0, z0, model)
        if j is None:
            nan = math.nan
            out.append(IdentifiedMode(row, nan, nan, nan, nan, analytic * 1e6, nan, nan))
            continue
        f1, z1 = float(model.freq_hz[j]), float(model.damping[j])
        lo, hi = _local_band(f1, z1)

        def synth(f: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            return np.abs(model.synthesise(np.atleast_1d(f))[0, 0])
        measured = maximise_near_poles(synth, model.poles, lo, hi).value
        out.append(IdentifiedMode(row, f1, z1, f1 / f0 - 1.0, z1 / z0 - 1.0, analytic * 1e6,
                                  measured * 1e6, 20.0 * math.log10(measured / analytic)))
    return out


def figures(ident: Identified, folder: Path, tag: str) -> tuple[Path, Path]:
    """Stability diagram and identified-vs-measured FRF of a damping run (PNG files)."""
    run, model = ident.run, ident.model
    return (ema_plots.stability_plot(model, run.freq, run.H, folder / f'stability_{tag}.png',
                                       title=f'{tag}: stability diagram ({run.estimator})'),
            ema_plots.synthesis_plot(model, run.freq, run.H, run.labels, run.units[0],
                                       folder / f'identified_frf_{tag}.png',
                                       title=f'{tag}: measured and identified FRF'))


def settle_rows(plant: PlantModel | DrivenPlant, laws: Sequence[Any], dt: float, direction: str,
                poles: tuple[LoopPoles, LoopPoles] | None = None) -> list[ModeDamping]:
    """
    The :data:`SETTLE_MODES` modes with the largest terms in TCP dd (their decay times).

    ``poles``: :func:`pentapod_damper.study.damping.loop_poles` of the same loop, if already
    computed.
    """
    return damping.damping_rows(plant, laws, dt, directions=direction, count=SETTLE_MODES,
                                poles=poles)
