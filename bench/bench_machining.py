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
  plant with a TCP damper law (the cost a cutting node adds to a lockstep step, without ROS);
* lockstep runs of the plant node with the cutting node, against the plant node with the
  exciter node (random force), in separate processes and composed (one process): best of
  interleaved rounds, steps/s of the plant's loop (its trace's wall time). The cutting node
  reads the TCP state, so the plant publishes /pentapod/tcp_state every step, which the
  exciter (answering /clock) does not need: part of what a closed-loop source costs.
"""
from __future__ import annotations

import math
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # run from a checkout
from pentapod_damper.laws import tcp_damper  # noqa: E402
from pentapod_sim.machining.cutting_process import CuttingProcess  # noqa: E402
from pentapod_sim.machining.lobes import milling_limit, StabilityLimit  # noqa: E402
from pentapod_sim.machining.materials import load_machining  # noqa: E402
from pentapod_sim.machining.tcp_frf import plant_poles, resonance_grid, tcp_frf  # noqa: E402
from pentapod_sim.plant.build import build_plant  # noqa: E402
from pentapod_sim.scenario.files import dump_params  # noqa: E402
from pentapod_sim.scenario.runner import run_scenario  # noqa: E402
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
    rows += lockstep_rows(plant, cond, quick)
    return rows


def _lockstep(folder: Path, model_file: Path, source: str, params: dict, steps: int,
              composed: bool) -> float:
    """Steps/s of one lockstep run: the plant node and one source node."""
    trace = folder / f'trace_{source}_{int(composed)}.npz'
    doc = {'/**': {'ros__parameters': {'sample_rate': 5000.0}},
           source: {'ros__parameters': params},
           'plant': {'ros__parameters': {'model_file': str(model_file), 'steps': steps,
                                         'sources': [source], 'output_file': str(trace),
                                         'startup_timeout': 60.0, 'loop_check': 'off'}}}
    path = folder / f'{source}.yaml'
    path.write_text(dump_params(doc))
    code = run_scenario(path, {}, 600.0, log_dir=folder / f'logs_{source}', composed=composed)
    if code != 0:
        raise RuntimeError(f'{source} run failed; logs in {folder}')
    with np.load(trace) as data:
        return steps / float(data['wall_time'])


def lockstep_rows(plant, cond, quick: bool) -> list[dict]:
    """Plant + cutting node against plant + exciter node, separate processes and composed."""
    steps, rounds = (3000, 1) if quick else (20000, 3)
    cutting = {'operation': OPERATION, 'spindle_speed': cond.spindle_speed,
               'axial_depth': cond.axial_depth}
    exciter = {'kind': 'random', 'amplitude': 100.0, 'direction': [1.0, 0.0, 0.0],
               'f_start': 2.0, 'f_end': 400.0, 'duration': steps / 5000.0}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model_file = plant.save(folder / 'plant_P1.npz')
        for composed in (False, True):
            best = {'cutting': 0.0, 'exciter': 0.0}
            for _ in range(rounds):
                for source, params in (('cutting', cutting), ('exciter', exciter)):
                    rate = _lockstep(folder, model_file, source, params, steps, composed)
                    best[source] = max(best[source], rate)
            where = 'composed (one process)' if composed else 'separate processes'
            rows.append(_row(f'lockstep plant + cutting node, {where}', best['cutting'],
                             best['exciter'], f'lockstep plant + exciter node, {where}',
                             'steps/s', f'P1, {plant.n_modes} modes, {steps} steps at 5 kHz, '
                             f'{OPERATION} at {cond.spindle_speed:.0f} rpm, '
                             f'{cond.axial_depth * 1e3:g} mm deep; best of {rounds} '
                             'interleaved rounds; the cutting node needs the TCP state '
                             'every step, the exciter only /clock'))
    return rows


if __name__ == '__main__':
    for r in run(quick='--quick' in sys.argv):
        print(f'{r["name"]:40s} {r["value"]:.4g} {r["unit"]} vs {r["baseline_value"]:.4g} '
              f'({r["baseline"]}): {r["ratio"]:.2f}x  [{r["note"]}]')
