"""
Benchmark of the study's lockstep testbed runs (pentapod_damper.study.runs).

Each row is one FRF run of the study as the study starts it (:func:`run_on_testbed`: the
scenario with the study's settings, every node composed in one process forked warm, the
recorder writing the bag), timed by the plant's own loop (its log line ``ran N of N steps in
T s wall``), against the same plant and the same control laws stepped offline without ROS
(:func:`pentapod_sim.sim.closed_loop.simulate`) in the same round. The ratio is the share of
the plain loop's speed the ROS run keeps: what the nodes' per-step path (publishing, the
in-process hand-off, the sources' message handling, the recorder) costs on top of the
arithmetic. A change that makes that path slower lowers it, whatever the machine's load.
Best of interleaved rounds.
"""
from __future__ import annotations

import os
from pathlib import Path
import re
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # run from a checkout
from pentapod_damper.scenario_laws import scenario_laws  # noqa: E402
from pentapod_damper.study import runs  # noqa: E402
from pentapod_damper.study.config import load_study_config  # noqa: E402
from pentapod_damper.study.stages import build_model  # noqa: E402
from pentapod_sim.scenario.files import read_scenario  # noqa: E402
from pentapod_sim.sim.closed_loop import simulate  # noqa: E402
from pentapod_sim.sim.stepping import DiscretePlant  # noqa: E402

#: The study's scenarios timed: a strut damper pair (reads the strut states, the heaviest
#: per-step message) and the TCP damper (reads the TCP state).
SCENARIOS = ('strut_damping_12', 'tcp_damping')
LOOP_LINE = re.compile(r'ran (\d+) of \d+ steps in ([0-9.]+) s wall')


def _loop_steps_per_s(run_dir: Path) -> float:
    """Steps/s of the plant's loop, from its log line in the run's logs."""
    text = ''.join(p.read_text(errors='replace') for p in sorted(run_dir.glob('logs/*.log')))
    found = LOOP_LINE.search(text)
    if found is None:
        raise RuntimeError(f'no loop summary of the plant in {run_dir / "logs"}')
    return int(found.group(1)) / float(found.group(2))


def run(quick: bool = False) -> list[dict]:
    """Study FRF runs against the offline loop of the same plant and laws."""
    rounds = 1 if quick else 3
    cfg = load_study_config(positions=('P1',), period=0.25 if quick else None)
    rows = []
    load = os.getloadavg()[0]          # the ratio holds under load, the absolute figures not
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        model = build_model(cfg, out, 'P1')
        n_steps = int(round(cfg.duration * cfg.sample_rate))
        for scenario in SCENARIOS:
            laws_of = read_scenario(scenario).sections
            best_ros, best_loop = 0.0, 0.0
            for _ in range(rounds):
                result = runs.run_on_testbed(scenario, 'P1', model.model_file, model.model_hash,
                                             cfg, out)
                best_ros = max(best_ros, _loop_steps_per_s(result.bag.parent))
                plant = DiscretePlant(model.plant.discretize(cfg.dt))
                laws = scenario_laws(laws_of, cfg.dt)
                excitation = np.zeros((n_steps, len(model.plant.input_names)))
                t0 = time.perf_counter()
                simulate(plant, laws, excitation)
                best_loop = max(best_loop, n_steps / (time.perf_counter() - t0))
            rows.append({
                'name': f'FRF run {scenario}, composed and recorded, as the study runs it',
                'value': best_ros, 'unit': 'steps/s',
                'baseline': 'the same plant and laws stepped offline (closed_loop.simulate)',
                'baseline_value': best_loop, 'ratio': best_ros / best_loop,
                'note': (f'P1, {model.plant.n_modes} modes, {n_steps} steps at '
                         f"{cfg.sample_rate:g} Hz; the plant loop's own wall time (start-up "
                         'and bag closing left out); exciter, dampers and recorder in one '
                         f'process forked warm; best of {rounds} interleaved rounds; load average '
                         f'{load:.1f} on {os.cpu_count()} CPUs at the start')})
    return rows


if __name__ == '__main__':
    for row in run('--quick' in sys.argv):
        print(row)
