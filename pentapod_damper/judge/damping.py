"""
Damping per mode: the baseline's dominant modes, found again in every controller's run.

The dominant modes of a direction are the ``count`` modes of the plant whose terms in the TCP
compliance along it peak highest inside the multisine band (open loop, modal formula
``|c_d,i b_i| / (2 zeta_i omega_i^2)``). In a controller's run each is paired with one
identified pole:

* a controller that published its linear model (recorded in the bag) has analytic closed-loop
  poles (:func:`pentapod_sim.sim.loop_poles.closed_loop_poles`, each paired with its open-loop
  mode by MAC); the identified pole nearest to the mode's closed-loop pole is taken if it lies
  within 0.5 % or one half-power bandwidth of it (the study's rule);
* a black box has none: its identified poles are paired with the baseline's identified poles of
  the dominant modes by a one-to-one assignment (Hungarian) on the frequency distance (within
  ``pair_tolerance``) and the MAC of the identified TCP x, y, z residues.

A mode without a partner is reported as not identified (NaN), never replaced by a neighbour.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from pentapod_damper.judge.measure import MultisineRun
from pentapod_damper.judge.models import ModeLabel, PositionModel
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.loop_poles import closed_loop_poles, LoopPoles, mac_matrix

#: The study's pairing of an identified pole with an analytic one: within this relative
#: frequency distance, or within this many half-power bandwidths (2 zeta f).
PAIR_TOLERANCE, PAIR_BANDWIDTHS = 0.005, 1.0


@dataclass(frozen=True)
class Pole:
    """Natural frequency [Hz] and damping ratio [-] (NaN: none)."""

    freq_hz: float
    zeta: float


NONE = Pole(math.nan, math.nan)


@dataclass(frozen=True)
class DominantMode:
    """A dominant open-loop mode of one TCP direction."""

    direction: str
    rank: int
    plant_mode: int            # 0-based
    label: ModeLabel
    open: Pole


def dominant_modes(pos: PositionModel, direction: str, band: Sequence[float],
                   count: int) -> list[DominantMode]:
    """The ``count`` open-loop modes with the highest peaks in TCP dd inside ``band``."""
    plant = pos.plant
    out = plant.output_names.index(f'tcp_displacement_{direction}')
    inp = plant.input_names.index(f'tcp_force_{direction}')
    omega, zeta = plant.omega, plant.zeta
    peak = np.abs(plant.c_disp[out] * plant.b[:, inp]) / (2 * zeta * omega ** 2)
    f = plant.frequencies_hz
    cand = np.flatnonzero((f >= band[0]) & (f <= band[1]))
    top = cand[np.argsort(-peak[cand])][:count]
    return [DominantMode(direction, rank, int(i), pos.label(int(i)),
                         Pole(float(f[i]), float(zeta[i])))
            for rank, i in enumerate(top, 1)]


def analytic_poles(pos: PositionModel, models: Sequence[DiscreteController],
                   dt: float) -> LoopPoles:
    """Closed-loop poles of the sampled loop with the controllers' models (open loop: [])."""
    return closed_loop_poles(pos.plant, list(models), dt)


def analytic_pole(poles: LoopPoles, mode: DominantMode) -> Pole:
    """The closed-loop pole of a dominant mode (NONE if no pole pairs with it)."""
    j = poles.of_mode(mode.plant_mode)
    return NONE if j < 0 else Pole(float(poles.freq_hz[j]), float(poles.zeta[j]))


def _s(pole: Pole) -> complex:
    w = 2 * math.pi * pole.freq_hz
    return complex(-pole.zeta * w, w * math.sqrt(max(1.0 - pole.zeta ** 2, 0.0)))


def near_analytic(run: MultisineRun, target: Pole) -> Pole:
    """The identified pole nearest an analytic one, within the study's tolerance."""
    model = run.model
    if not len(model.freq_hz) or not math.isfinite(target.freq_hz):
        return NONE
    ident = [Pole(float(f), float(z)) for f, z in zip(model.freq_hz, model.damping)]
    j = int(np.argmin([abs(_s(p) - _s(target)) for p in ident]))
    tol = max(PAIR_TOLERANCE * target.freq_hz,
              PAIR_BANDWIDTHS * 2.0 * target.zeta * target.freq_hz)
    return ident[j] if abs(ident[j].freq_hz - target.freq_hz) <= tol else NONE


def _shapes(run: MultisineRun) -> npt.NDArray[np.complex128]:
    """(3, R) identified residues of the TCP x, y, z outputs per pole."""
    return run.column.residues[:, 0, :]


def paired_with_baseline(run: MultisineRun, base: MultisineRun, base_poles: Sequence[Pole],
                         tolerance: float) -> list[Pole]:
    """
    A black box's identified poles paired one to one with the baseline's (module docstring).

    ``base_poles`` are the baseline's identified poles of the dominant modes (NONE allowed).
    """
    model = run.model
    out = [NONE] * len(base_poles)
    if not len(model.freq_hz):
        return out
    base_idx = []
    for p in base_poles:
        hit = np.flatnonzero(np.isclose(base.model.freq_hz, p.freq_hz, rtol=0, atol=1e-12))
        base_idx.append(int(hit[0]) if hit.size and math.isfinite(p.freq_hz) else -1)
    mac = mac_matrix(_shapes(run), _shapes(base))                 # (R_run, R_base)
    cost = np.full((len(model.freq_hz), len(base_poles)), 1e6)
    for k, (p, j) in enumerate(zip(base_poles, base_idx)):
        if j < 0:
            continue
        dist = np.abs(model.freq_hz - p.freq_hz) / (tolerance * p.freq_hz)
        ok = dist <= 1.0
        cost[ok, k] = (1.0 - mac[ok, j]) + dist[ok]
    rows, cols = linear_sum_assignment(cost)
    for r, k in zip(rows, cols):
        if cost[r, k] < 1e6:
            out[k] = Pole(float(model.freq_hz[r]), float(model.damping[r]))
    return out
