"""
Benchmark of the chatter analyses (pentapod_sim.machining).

Rows, on the P1 plant's TCP FRF (open loop, the resonance grid of
:func:`pentapod_sim.machining.tcp_frf.resonance_grid`, 1-1000 Hz) and the operation
aluminium_half_down of config/machining.yaml:

* the lobe diagram over 1,000-24,000 rpm: :meth:`StabilityLimit.envelope` (every grid interval
  and lobe mapped to the speeds it crosses, all at once) against a python loop over the
  speeds that does the same interpolation one speed at a time (numpy over the frequencies);
  both give the same envelope (checked to 1e-9);
* the plant stepped offline with the cutting process as its force source, against the same
  plant with a TCP damper law (the cost a cutting node adds to a lockstep step, without ROS).
"""
from __future__ import annotations

import math
from pathlib import Path
import sys
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # run from a checkout
from pentapod_damper.laws import tcp_damper  # noqa: E402
from pentapod_sim.machining.cutting_process import CuttingProcess  # noqa: E402
from pentapod_sim.machining.lobes import milling_limit, StabilityLimit  # noqa: E402
from pentapod_sim.machining.materials import load_machining  # noqa: E402
from pentapod_sim.machining.tcp_frf import plant_poles, resonance_grid, tcp_frf  # noqa: E402
from pentapod_sim.plant.build import build_plant  # noqa: E402
from pentapod_sim.sim.closed_loop import simulate  # noqa: E402
from pentapod_sim.sim.stepping import DiscretePlant  # noqa: E402

OPERATION = 'aluminium_half_down'


def _best(func, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = func()
        times.append(time.perf_counter() - t0)
    return min(times), out


def envelope_by_speed_loop(limit: StabilityLimit, speeds: np.ndarray) -> np.ndarray:
    """The lobe envelope one speed at a time: the baseline of the vectorised envelope."""
    w = 2 * math.pi * limit.freq
    out = np.full(speeds.size, math.inf)
    for s, n in enumerate(speeds):
        period = 60.0 / (limit.teeth * n)
        for a, eps in zip(limit.depth, limit.phase):
            g = (w * period - eps) / (2 * math.pi)
            g0, g1, a0, a1 = g[:-1], g[1:], a[:-1], a[1:]
            k_min = np.maximum(np.ceil(np.minimum(g0, g1)), 0)
            k_max = np.floor(np.maximum(g0, g1))
            has = np.isfinite(a0) & np.isfinite(a1) & (k_min <= k_max)
            left_low = a0 <= a1                      # the lower end decides the k nearest it
            k = np.where(left_low == (g0 <= g1), k_min, k_max)
            with np.errstate(invalid='ignore', divide='ignore'):
                frac = np.where(g1 == g0, 0.0, (k - g0) / (g1 - g0))
            depth = a0 + np.clip(frac, 0, 1) * (a1 - a0)
            if np.any(has):
                out[s] = min(out[s], float(np.min(depth[has])))
    return out


def _row(name, ours, base, baseline, unit, note):
    return {'name': name, 'value': ours, 'unit': unit, 'baseline': baseline,
            'baseline_value': base, 'ratio': base / ours if unit == 's' else ours / base,
            'note': note}


def run(quick: bool = False) -> list[dict]:
    """Time the lobe diagram and the offline cutting loop against their baselines."""
    plant = build_plant('P1')
    table = load_machining()
    cut = table.milling_cut(OPERATION)
    freq = resonance_grid(plant_poles(plant), 1.0, 1000.0)
    frf = tcp_frf(plant, freq)
    speeds = np.linspace(1000.0, 24000.0, 200 if quick else 2000)
    repeat = 1 if quick else 3

    def vectorised():
        return milling_limit(frf, cut).envelope(speeds).depth
    ours, depth = _best(vectorised, repeat)
    base, ref = _best(lambda: envelope_by_speed_loop(milling_limit(frf, cut), speeds), 1)
    if not np.allclose(depth, ref, rtol=1e-9, atol=0):
        raise RuntimeError('the vectorised envelope differs from the loop over speeds')
    rows = [_row('lobe diagram (envelope over all lobes)', ours, base,
                 'python loop over speeds', 's',
                 f'P1 TCP x-y FRF, {freq.size} frequencies, {speeds.size} speeds, '
                 f'{OPERATION}; same envelope')]
    dt, n_steps = 1.0 / 5000.0, 5000 if quick else 20000
    speed = 1500.0                                  # 4 teeth: 50 steps per tooth at 5 kHz
    cond = table.conditions(OPERATION, speed, 0.2e-3)

    def stepped(law):
        discrete = DiscretePlant(plant.discretize(dt))
        return lambda: simulate(discrete, [law()], np.zeros((n_steps, len(plant.input_names))))
    cutting, _ = _best(stepped(lambda: CuttingProcess(cond, dt)), repeat)
    damper, _ = _best(stepped(lambda: tcp_damper(['x', 'y'], 2e4)), repeat)
    rows.append(_row('offline plant + cutting process', n_steps / cutting, n_steps / damper,
                     'offline plant + TCP damper law', 'steps/s',
                     f'P1, {plant.n_modes} modes, {n_steps} steps at 5 kHz, {OPERATION} at '
                     f'{speed:.0f} rpm, 0.2 mm deep (pentapod_sim.sim.closed_loop.simulate)'))
    return rows


if __name__ == '__main__':
    for r in run(quick='--quick' in sys.argv):
        print(f'{r["name"]:40s} {r["value"]:.4g} {r["unit"]} vs {r["baseline_value"]:.4g} '
              f'({r["baseline"]}): {r["ratio"]:.2f}x  [{r["note"]}]')
