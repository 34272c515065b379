"""
Benchmark of the modal identification (pentapod_sim.analysis.ema.identify) against sdypy-ema.

Data: the test systems of test/modal_systems.py (2-DOF chain, 0.1 % and 2 %; 10-mode model,
0.1 % to 2 %), FRFs by synchronous averaging of a periodic multisine with 2 % white output
noise. Ours runs the whole non-interactive chain (pLSCF orders 1-60, automatic selection, LSFD;
with and without pole refinement); the baseline ``sdypy.EMA.Model`` (LSCF orders 2-60, LSFD)
is given the true natural frequencies for its pole picking (``select_closest_poles``, f_window
2 Hz), which it needs because it has no automatic selection. Each row's note gives both
accuracies (largest relative error of frequency and damping ratio over the modes); ratio =
baseline time / ours.
Without sdypy-ema installed (``pip install sdypy-ema``, see requirements-dev.txt) the rows
have no baseline.
"""
from __future__ import annotations

import contextlib
import io
from pathlib import Path
import sys
import time
import warnings

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))   # run from a checkout
sys.path.insert(0, str(ROOT / 'test'))
from modal_systems import multisine, periodic_response, TenModes, TwoDof  # noqa: E402

from pentapod_sim.analysis.ema.identify import identify_modes  # noqa: E402
from pentapod_sim.analysis.frf.periodic import synchronous_frf  # noqa: E402

DT = 1e-3  # s
CASES = {'2-DOF': (TwoDof, 4000, 100.0), '10 modes': (TenModes, 10000, 200.0)}


def _frfs(system, period_steps: int, f_high: float) -> tuple:
    bins = np.arange(int(2 * period_steps * DT), int(f_high * period_steps * DT) + 1)
    u, y = periodic_response(system, multisine(period_steps, bins), DT, 9, 0.02,
                             np.random.default_rng(0))
    frfs = [synchronous_frf(u, out, DT, period_steps, settle_periods=1) for out in y]
    return frfs[0].freq, np.array([r.H for r in frfs]), np.array([r.noise_std for r in frfs])


def _errors(freq_hz, damping, system) -> str:
    freq_hz, damping = np.asarray(freq_hz, float), np.asarray(damping, float)
    if len(freq_hz) == 0 or np.any(freq_hz <= 0):
        return f'{np.sum(freq_hz > 0)} of {len(system.freq_hz)} modes found'
    k = [int(np.argmin(np.abs(system.freq_hz - f))) for f in freq_hz]
    err_f = np.max(np.abs(freq_hz / system.freq_hz[k] - 1))
    err_z = np.max(np.abs(damping / system.damping[k] - 1))
    return f'{len(set(k))}/{len(system.freq_hz)} modes, f err {err_f:.1e}, zeta err {err_z:.1%}'


def _sdypy(freq, h, system):
    from sdypy import EMA  # optional baseline
    with warnings.catch_warnings(), contextlib.redirect_stderr(io.StringIO()):
        warnings.simplefilter('ignore')
        model = EMA.Model(frf=h, freq=freq, lower=freq[0], upper=freq[-1], pol_order_high=30,
                          frf_form='receptance')
        model.get_poles(method='lscf', show_progress=False)
        model.select_closest_poles(list(system.freq_hz), f_window=2)
        model.get_constants(method='lsfd')
    return model.nat_freq, model.nat_xi


def _best(func, repeat: int) -> tuple:
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = func()
        times.append(time.perf_counter() - t0)
    return min(times), result


def run(quick: bool = False) -> list[dict]:
    """Time and accuracy of our identification and of sdypy-ema on the two test systems."""
    repeat = 1 if quick else 3
    try:
        import sdypy.EMA  # noqa: F401
        have_baseline = True
    except ImportError:
        have_baseline = False
    rows = []
    for name, (make, period_steps, f_high) in CASES.items():
        system = make()
        freq, h, sigma = _frfs(system, period_steps, f_high)
        for refine in (True, False):
            ours, model = _best(lambda: identify_modes(freq, h, sigma=sigma, refine=refine),
                                repeat)
            note = (f'{len(freq)} lines, {h.shape[0]} outputs; '
                    f'ours: {_errors(model.freq_hz, model.damping, system)}')
            row = {'name': f'{name}: pLSCF + auto selection + LSFD'
                           f'{" + refinement" if refine else ""}',
                   'value': ours, 'unit': 's', 'baseline': 'sdypy-ema LSCF+LSFD, true f given',
                   'baseline_value': None, 'ratio': None, 'note': note}
            if have_baseline:
                base, (fn, xi) = _best(lambda: _sdypy(freq, h, system), repeat)
                row.update(baseline_value=base, ratio=base / ours,
                           note=f'{note}; sdypy-ema: {_errors(fn, xi, system)}')
            rows.append(row)
    return rows


if __name__ == '__main__':
    for r in run(quick='--quick' in sys.argv):
        base = (f'{r["baseline_value"]:.3g} s ({r["baseline"]}): {r["ratio"]:.2f}x'
                if r['ratio'] else 'no baseline (sdypy-ema not installed)')
        print(f'{r["name"]:55s} {r["value"]:.3g} s vs {base}  [{r["note"]}]')
