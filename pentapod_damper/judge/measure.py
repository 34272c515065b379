"""
What a multisine run's bag gives.

The TCP FRFs at the lines, the identified modes, the peak and the RMS of the compliance, and
the analytic sampled-loop reference where a model exists.

The FRFs come from the stored excitation (synchronous averaging over whole periods after the
settling periods, :func:`pentapod_sim.analysis.frf.from_run.frfs_from_bag`) for the TCP
displacement along x, y and z per force along the excited direction. The modes are identified
from the direct FRF (pLSCF + LSFD, every stable cluster counted, unweighted: the testbed has no
measurement noise) as the study does; the residues of the other two outputs are fitted at the
same poles (LSFD), so the identified model gives the whole column of the TCP FRF matrix.

* **Peak**: the identified model's direct FRF maximised near its poles in the band (the lines,
  1 / period apart, do not resolve a 0.1 %-damped resonance: 0.05 Hz wide at 27 Hz).
* **RMS**: ``sqrt(mean |H|^2)`` over the excited lines: with the multisine's equal line
  amplitudes, the RMS displacement per RMS force in steady state. Baseline and controllers share
  the lines, so their ratio compares the same thing; the analytic reference is taken on the
  same lines.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_damper.study.analytic import SampledPairFrf
from pentapod_sim.analysis.ema.identify import identify_modes, ModalModel
from pentapod_sim.analysis.ema.lsfd import lsfd, ResidueFit
from pentapod_sim.analysis.ema.poles import Tolerances
from pentapod_sim.analysis.frf.from_run import frfs_from_bag
from pentapod_sim.errors import BagError
from pentapod_sim.interface import TCP_STATE
from pentapod_sim.plant.frf_peaks import maximise_near_poles, Peak
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import DiscreteController

AXES = ('x', 'y', 'z')
OUTPUTS = [f'{TCP_STATE}.position.tcp_{a}' for a in AXES]


@dataclass
class MultisineRun:
    """
    One analysed multisine run.

    Attributes
    ----------
    direction : str
        Excited TCP direction.
    freq : (F,) ndarray
        Excited lines [Hz].
    H : (3, F) complex ndarray
        TCP displacement x, y, z per force along ``direction`` [m/N].
    transient : (3, F) ndarray
        Transient error estimate per line (first against second half of the periods) [m/N].
    model : ModalModel
        Modes identified from the direct FRF.
    column : ResidueFit
        The identified poles fitted to all three outputs.
    peak : Peak
        Peak of the identified direct FRF in the band [m/N].
    rms : float
        RMS of |H_dd| over the lines [m/N].
    periods : int
        Periods averaged.
    """

    direction: str
    freq: npt.NDArray[np.float64]
    H: npt.NDArray[np.complex128]
    transient: npt.NDArray[np.float64]
    model: ModalModel
    column: ResidueFit
    peak: Peak
    rms: float
    periods: int

    @property
    def direct(self) -> int:
        """Row of the direct FRF."""
        return AXES.index(self.direction)

    def synthesise(self, freq: npt.ArrayLike, output: str | None = None
                   ) -> npt.NDArray[np.complex128]:
        """Identified FRF of ``output`` (x, y, z; default the direct one) at ``freq`` [Hz]."""
        row = AXES.index(output or self.direction)
        return self.column.synthesise(np.atleast_1d(np.asarray(freq, dtype=float)))[row, 0]

    @property
    def settled(self) -> float:
        """Largest transient error relative to |H| near the direct FRF's peak line [-]."""
        row = self.direct
        top = int(np.argmax(np.abs(self.H[row])))
        return float(self.transient[row, top] / abs(self.H[row, top]))


def _peak(fit: ResidueFit, row: int, poles: npt.NDArray[np.complex128],
          band: Sequence[float]) -> Peak:
    def mag(f: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.abs(fit.synthesise(np.atleast_1d(f))[row, 0])
    return maximise_near_poles(mag, poles, float(band[0]), float(band[1]))


def analyse_multisine(bag: Path, direction: str, band: Sequence[float],
                      max_order: int) -> MultisineRun:
    """
    FRFs, modes, peak and RMS of one multisine run.

    Raises
    ------
    BagError
        If the bag lacks the excitation record or the identification finds no mode.
    """
    run = frfs_from_bag(bag, OUTPUTS)
    row = AXES.index(direction)
    lines = (run.freq >= band[0]) & (run.freq <= band[1])
    freq, h = run.freq[lines], run.H[:, 0, lines]
    transient = (run.transient[:, 0, lines] if run.transient is not None
                 else np.zeros(h.shape))
    try:
        model = identify_modes(freq, h[row], band=tuple(band), sigma=None,
                               frf_form=run.frf_form, orders=range(1, max_order + 1),
                               tol=Tolerances(min_stable_fraction=0.0))
    except ValueError as err:
        raise BagError(f'{bag}: modal identification failed: {err}') from None
    column = lsfd(freq, h[:, None, :], model.poles, run.frf_form)
    peak = _peak(column, row, model.poles, band)
    rms = float(np.sqrt(np.mean(np.abs(h[row]) ** 2)))
    return MultisineRun(direction, freq, h, transient, model, column, peak, rms,
                        run.n_averages)


class ModelLaw:
    """A published linear model as a law of the offline loop (``discrete_model``)."""

    def __init__(self, model: DiscreteController) -> None:
        self.model = model
        self.sensor_ports = list(model.sensor_ports)
        self.actuator_ports = list(model.actuator_ports)

    def discrete_model(self) -> DiscreteController:
        """The model itself."""
        return self.model


@dataclass
class Analytic:
    """The analytic sampled-loop reference of one direction: FRF on the lines, peak, RMS."""

    H: npt.NDArray[np.complex128]
    peak: Peak
    rms: float


def analytic_reference(plant: PlantModel, models: Sequence[DiscreteController], dt: float,
                       direction: str, freq: npt.NDArray[np.float64],
                       band: Sequence[float]) -> Analytic:
    """
    The sampled loop of the plant with the controllers' models, as the run steps it.

    ``models`` empty: the open loop (the baseline).
    """
    laws: list[Any] = [ModelLaw(m) for m in models]
    frf = SampledPairFrf(plant, laws, dt, f'tcp_displacement_{direction}',
                         f'tcp_force_{direction}')
    h = frf(freq)
    peak = maximise_near_poles(lambda f: np.abs(frf(f)), frf.poles, float(band[0]),
                               float(band[1]))
    return Analytic(h, peak, float(np.sqrt(np.mean(np.abs(h) ** 2))))


def db(ratio: float) -> float:
    """20 log10 of a ratio (NaN for a non-positive one)."""
    return 20.0 * math.log10(ratio) if ratio > 0 and math.isfinite(ratio) else math.nan
