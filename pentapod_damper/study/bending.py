"""
Two readings of the paper's strut bending damper, side by side, with their gain sweeps.

* **rotational**: a moment pair about e2/e3 from the rotation of the strut's WP end relative
  to its rear end (``strut<i>_bending_moment_<k>``, b [N m s/rad]; paper Fig. 6 read as a
  rotational damper). Its port spans the strut's overhang behind the BP joint.
* **chord**: a lateral force along e2/e3 at the chord point (mid-span by default) against
  the chord between the strut's joints (``strut<i>_chord_force_<k>``, b [N s/m]; the paper's
  gains quoted in N s/m).

For each model and position: the exact TCP peak reduction over the gain (all struts and
struts 1+2), the optimal gain (the one that minimises the all-struts exact peak), and at that
gain and at the paper's b = 20,000 the share of the all-struts improvement that struts 1+2
achieve (exact peak and RMS of |H| over the band). Continuous loop with ideal viscous dampers.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize_scalar

from pentapod_damper.study.analytic import continuous_frf, improvement_share, peak_and_rms
from pentapod_damper.study.records import BendingComparison, BendingModel
from pentapod_sim.plant.frf_peaks import exact_peak, plant_pair_frf
from pentapod_sim.plant.model import PlantModel

FloatArray = npt.NDArray[np.float64]
#: Model name -> (input port pattern, gain unit, sweep gains).
MODELS: dict[str, tuple[str, str, FloatArray]] = {
    'rotational': ('strut{i}_bending_moment_{k}', 'N m s/rad', np.geomspace(10.0, 1e5, 25)),
    'chord': ('strut{i}_chord_force_{k}', 'N s/m', np.geomspace(1e2, 1e6, 25)),
}
#: The paper's strut damping [N s/m], applied to both models as written.
PAPER_GAIN = 20000.0
ALL_STRUTS = (1, 2, 3, 4, 5)
STRUTS_12 = (1, 2)


def dampers(model: str, struts: Sequence[int], gain: float) -> dict[str, float]:
    """Input port -> gain of the model's dampers on both lateral axes of ``struts``."""
    pattern = MODELS[model][0]
    return {pattern.format(i=i, k=k): float(gain) for i in struts for k in (2, 3)}


def peak(plant: PlantModel, model: str, struts: Sequence[int], gain: float, direction: str,
         band: tuple[float, float], grid: FloatArray) -> float:
    """Exact TCP peak [m/N] with the model's dampers on ``struts``."""
    frf = plant_pair_frf(plant, f'tcp_displacement_{direction}', f'tcp_force_{direction}',
                         dampers(model, struts, gain))
    return exact_peak(frf, band[0], band[1], grid).value


def rms(plant: PlantModel, model: str, struts: Sequence[int], gain: float, direction: str,
        band: tuple[float, float], grid: FloatArray) -> float:
    """RMS of |H| over the band on the grid [m/N]."""
    h = continuous_frf(plant, dampers(model, struts, gain), grid,
                       f'tcp_displacement_{direction}', f'tcp_force_{direction}')
    return peak_and_rms(h, grid, *band)[1]


def sweep(plant: PlantModel, model: str, direction: str, band: tuple[float, float],
          grid: FloatArray) -> dict[str, FloatArray]:
    """Exact peaks [m/N] over the model's sweep gains, all struts and struts 1+2."""
    gains = MODELS[model][2]
    return {label: np.array([peak(plant, model, struts, g, direction, band, grid)
                             for g in gains])
            for label, struts in (('all struts', ALL_STRUTS), ('struts 1, 2', STRUTS_12))}


def optimal_gain(plant: PlantModel, model: str, peaks_all: FloatArray, direction: str,
                 band: tuple[float, float], grid: FloatArray) -> float:
    """Gain that minimises the all-struts exact peak (bounded search around the sweep's best)."""
    gains = MODELS[model][2]
    i = int(np.argmin(peaks_all))
    lo, hi = np.log10(gains[max(i - 1, 0)]), np.log10(gains[min(i + 1, gains.size - 1)])
    res = minimize_scalar(lambda lg: peak(plant, model, ALL_STRUTS, 10 ** lg, direction, band,
                                          grid), bounds=(lo, hi), method='bounded',
                          options={'xatol': 1e-3})
    return float(10 ** res.x) if res.fun <= peaks_all[i] else float(gains[i])


def _at_gain(plant: PlantModel, model: str, gain: float, base_peak: float, base_rms: float,
             direction: str, band: tuple[float, float], grid: FloatArray
             ) -> tuple[float, float, float, float]:
    """Peak reduction all struts and struts 1+2, struts 1+2 share by peak and by RMS."""
    p = {s: peak(plant, model, st, gain, direction, band, grid)
         for s, st in (('all', ALL_STRUTS), ('12', STRUTS_12))}
    r = {s: rms(plant, model, st, gain, direction, band, grid)
         for s, st in (('all', ALL_STRUTS), ('12', STRUTS_12))}
    return (base_peak / p['all'], base_peak / p['12'],
            improvement_share(base_peak, p['12'], p['all']),
            improvement_share(base_rms, r['12'], r['all']))


def compare(plant: PlantModel, position: str, direction: str, band: tuple[float, float],
            grid: FloatArray) -> BendingComparison:
    """
    Both bending models at one position: optimal gains, reductions, shares and sweep curves.

    Per model: unit, optimal gain, exact peak reductions (all struts, struts 1+2) and
    struts-1+2 shares (peak, RMS) at the optimal gain and at the paper's b = 20,000; curves
    ``'<position>, <model>, <struts>'``: exact peak reduction over ``MODELS`` gains.
    """
    out = f'tcp_displacement_{direction}'
    base = plant_pair_frf(plant, out, f'tcp_force_{direction}')
    base_peak = exact_peak(base, band[0], band[1], grid).value
    base_rms = peak_and_rms(continuous_frf(plant, {}, grid, out, f'tcp_force_{direction}'),
                            grid, *band)[1]
    models, curves = [], {}
    for model, (_, unit, _) in MODELS.items():
        peaks = sweep(plant, model, direction, band, grid)
        for label, values in peaks.items():
            curves[f'{position}, {model}, {label}'] = base_peak / values
        best = optimal_gain(plant, model, peaks['all struts'], direction, band, grid)
        at = [_at_gain(plant, model, gain, base_peak, base_rms, direction, band, grid)
              for gain in (best, PAPER_GAIN)]
        models.append(BendingModel(position, model, unit, best, *at[0], *at[1]))
    return BendingComparison(position, models, curves)
