"""
Benchmark of the modal plant (pentapod_sim.plant.model, pentapod_sim.plant.frf).

Rows, all on the P1 plant with every mode below 750 Hz (same input for ours and baseline):
the modal-sum FRF against ``control.frequency_response`` of the same state space, the per-mode
ZOH discretisation against ``scipy.signal.cont2discrete`` on the full A, and the
closed-loop FRF via the eigen-decomposition against ``control.frequency_response``, and the
exact peak of a closed-loop FRF with and without the bound that skips resonances.
"""
from __future__ import annotations

from pathlib import Path
import sys
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # run from a checkout
import control  # noqa: E402
import scipy.signal as signal  # noqa: E402

from pentapod_sim.fe.assembly import build_model  # noqa: E402
from pentapod_sim.fe.machine_data import load_machine  # noqa: E402
from pentapod_sim.plant import frf, frf_peaks  # noqa: E402
from pentapod_sim.plant.build import load_reduction_config, plant_from_fe


def _best(func, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        func()
        times.append(time.perf_counter() - t0)
    return min(times)


def _row(name, ours, base, baseline, note):
    return {'name': name, 'value': ours, 'unit': 's', 'baseline': baseline,
            'baseline_value': base, 'ratio': base / ours, 'note': note}


def run(quick: bool = False) -> list[dict]:
    """Time FRF, ZOH and closed-loop FRF against python-control / scipy baselines."""
    cfg = load_reduction_config()
    plant, _ = plant_from_fe(build_model(load_machine(), 'P1'), cfg)
    tcp = plant.select(['tcp_force_x', 'tcp_force_y', 'tcp_force_z'],
                       ['tcp_displacement_x', 'tcp_displacement_y', 'tcp_displacement_z'])
    freq = np.linspace(0.5, 400.0, 500 if quick else 4000)
    w, repeat = 2 * np.pi * freq, 1 if quick else 3
    sys_c = tcp.to_statespace()
    ours = _best(lambda: frf.modal_frf(tcp, freq), repeat)
    base = _best(lambda: control.frequency_response(sys_c, w), repeat)
    note = f'{tcp.n_modes} modes, 3x3 TCP, {freq.size} freqs'
    rows = [_row('FRF modal sum (vectorised)', ours, base, 'control.frequency_response', note)]
    a, b, c, d = plant.state_matrices()
    ours = _best(lambda: plant.discretize(2e-4), repeat)
    base = _best(lambda: signal.cont2discrete((a, b, c, d), 2e-4, method='zoh'), repeat)
    rows.append(_row('ZOH per mode (batched 3x3 expm)', ours, base, 'scipy cont2discrete',
                     f'{plant.n_modes} modes, {len(plant.input_names)} inputs'))
    dampers = {f'strut{i}_bending_moment_{k}': 2e4 for i in range(1, 6) for k in (2, 3)}
    closed = frf.damper_feedback(plant, dampers)
    ours = _best(lambda: frf.closed_loop_frf(plant, dampers, freq), repeat)
    base = _best(lambda: control.frequency_response(closed, w), repeat)
    rows.append(_row('closed-loop FRF (eigen-decomposition)', ours, base,
                     'control.frequency_response', f'10 bending dampers, {plant.n_modes} modes, '
                     f'{len(plant.output_names)}x{len(plant.input_names)} ports'))
    rows.append(exact_peak_row(plant, dampers, freq, repeat))
    return rows


def exact_peak_row(plant, dampers: dict, freq: np.ndarray, repeat: int) -> dict:
    """Exact TCP peak with the bound that skips resonances, against searching every one."""
    pair = frf_peaks.plant_pair_frf(plant, 'tcp_displacement_x', 'tcp_force_x', dampers)

    def search(bound):
        return frf_peaks.maximise_near_poles(lambda f: np.abs(pair(f)), pair.poles, 2.0,
                                             400.0, freq, bound)
    pruned, every = search(pair.bound), search(None)
    if pruned != every:
        raise RuntimeError(f'the bound changed the peak: {pruned} against {every}')
    ours = _best(lambda: search(pair.bound), repeat)
    base = _best(lambda: search(None), repeat)
    return _row('exact peak (resonances skipped by their bound)', ours, base,
                'every resonance searched', f'TCP x, 10 bending dampers, {plant.n_modes} modes, '
                f'2-400 Hz, grid of {freq.size}; the same peak, {pruned.value:.6g} m/N at '
                f'{pruned.freq_hz:.6g} Hz (pentapod_sim.plant.frf_peaks)')


if __name__ == '__main__':
    for r in run(quick='--quick' in sys.argv):
        print(f'{r["name"]:40s} {r["value"]:.4g} s vs {r["baseline_value"]:.4g} s '
              f'({r["baseline"]}): {r["ratio"]:.1f}x  [{r["note"]}]')
