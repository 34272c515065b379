"""
Benchmark of the live view: the lockstep loop with and without it.

Lockstep runs of the plant node (demo model of 100 modes, 5 kHz) with one damper node, with and
without the live view node and a Foxglove WebSocket client subscribed to every channel
(test/fixtures/foxglove_client.py), in separate processes on a private ROS domain; once without
and once with a recorder in both runs. The figure is the plant's steps per wall second; the
ratio (with / without the live view) is 1 when the view costs the loop nothing.

The live view takes the plant's state topics and the sources' forces from the plant's display
batches (pentapod_sim/nodes/display_batch.py: one message per topic every 10 ms of simulated
time), so it adds no per-step publish to the plant or the damper: without a recorder the plant
publishes only strut_states per step (for the damper) with or without the view. And it
subscribes only while a client watches, so with no client it takes nothing from the run (the
plant does not wait for it then). Before the batches, the view's per-step subscriptions made
the plant publish two more state topics every step and the view decode 5,000 messages a
second per topic (0.79x, git history of bench/RESULTS.md).

Four kinds of runs, each without and with a recorder: no live view; the live view with no
client (its own cost: subscriptions, worker thread, server); the view and the Foxglove client
(test/fixtures/foxglove_client.py, a stand-in for the user's Foxglove on the same machine) at
normal priority; and the client at niceness +10 like the view. On two cores a client competes
for the CPU with the plant and its controller, so the rows with a client measure the machine as
much as the view. Kinds alternate in rounds, so drifts in the load of a shared machine hit all;
a row's figure is its best run, and its note lists the per-round ratios, whose spread is the
noise. Full: 10000 steps, 5 rounds; quick: 3000 steps, 1 round.
"""
from __future__ import annotations

from pathlib import Path
import re
import sys
import tempfile
import time

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import bench_plant  # noqa: E402  (also puts the checkout and test/ on sys.path)

from fixtures.demo_model import demo_model  # noqa: E402

RATE = 5000.0
CLIENT = HERE.parent / 'test' / 'fixtures' / 'foxglove_client.py'
#: Niceness of the client in the row that measures the view's own cost.
CLIENT_NICE = 10


def _row(name, value, unit, baseline, baseline_value, note=''):
    return {'name': name, 'value': value, 'unit': unit, 'baseline': baseline,
            'baseline_value': baseline_value,
            'ratio': value / baseline_value if baseline_value else float('nan'), 'note': note}


def _port(log: Path, timeout: float = 120.0) -> int:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        found = re.search(r'server on ws://[\d.]+:(\d+)', log.read_text() if log.exists() else '')
        if found:
            return int(found.group(1))
        time.sleep(0.1)
    raise RuntimeError(f'live view did not start: {log.read_text()}')


def lockstep(folder: Path, model_file: Path, steps: int, live: bool, record: bool,
             tag: str, client_nice: int | None = 0) -> float:
    """
    One lockstep run of plant + damper (+ recorder) (+ live view and client): steps/s.

    ``client_nice`` is the niceness the Foxglove client process runs at; None: no client
    (the view subscribes to the testbed topics all the same).
    """
    session = bench_plant.Session(folder)
    trace = folder / f'trace_{tag}.npz'
    try:
        session.node('pentapod_damper.nodes.damper_node', 'damper0', 'bending_struts:=[1]',
                     'bending_gain:=100.0')
        waits = []
        if record:
            session.node('pentapod_sim.nodes.recorder_node', 'recorder',
                         f'output_dir:={folder}', f'bag_name:=bag_{tag}')
            waits.append('recorder')
        if live:
            session.node('pentapod_sim.nodes.live_view_node', 'live_view', 'port:=0')
            port = _port(folder / 'live_view.log')
        if live and client_nice is not None:
            session.start(['-c', f'import os, runpy, sys; os.nice({client_nice}); '
                           'sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], '
                           "run_name='__main__')", str(CLIENT), f'ws://127.0.0.1:{port}'],
                          f'client_{tag}.log')
        if live and client_nice is not None:
            waits.append('live_view')     # it subscribes only while a client watches
        plant = session.node('pentapod_sim.nodes.plant_node', 'plant',
                             f'model_file:={model_file}', f'steps:={steps}',
                             f'sample_rate:={RATE}', 'sources:=[damper0]',
                             f"output_file:='{trace}'", 'startup_timeout:=120.0',
                             'wait_for_subscribers:=[' + ', '.join(waits) + ']')
        if plant.wait(timeout=900) != 0:
            raise RuntimeError((folder / 'plant.log').read_text())
    finally:
        session.close()
    with np.load(trace) as data:
        return steps / float(data['wall_time'])


#: Kinds of runs: (live view, client niceness or None for no client), row label.
KINDS = [((True, None), 'live view, no client'),
         ((True, 0), 'live view and 1 Foxglove client'),
         ((True, CLIENT_NICE), f'live view and 1 Foxglove client at niceness +{CLIENT_NICE}')]


def run(quick: bool) -> list[dict]:
    """
    Rows: steps/s with the live view against the same run without it.

    Runs of every kind alternate, ``repeats`` rounds; a row's figure is the best run of its kind
    against the best run without the view, and its note gives the ratios of the rounds (each
    run against the run without the view of the same round), whose spread is the noise of
    the machine.
    """
    steps, repeats = (3000, 1) if quick else (10000, 5)
    note = (f'{steps} steps of a 200-state demo model at {RATE:g} Hz, best of {repeats}; live '
            'view defaults (display batches of 10 ms, subscribed while a client watches, best '
            'effort, polled, nice +10, 100 Hz envelopes)')
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model_file = demo_model(100, seed=1).save(folder / 'model.npz')
        for record in (False, True):
            kinds = [(False, None)] + [kind for kind, _ in KINDS]
            runs: dict = {kind: [] for kind in kinds}
            for k in range(repeats):
                for kind in kinds:                 # alternate: drifts in load hit all
                    tag = f'{int(record)}{int(kind[0])}{kind[1]}_{k}'
                    runs[kind].append(lockstep(folder, model_file, steps, kind[0], record,
                                               tag, kind[1]))
            base = max(runs[False, None])
            with_rec = ' + recorder' if record else ''
            for kind, label in KINDS:
                rounds = np.array(runs[kind]) / np.array(runs[False, None])
                rows.append(_row(
                    f'lockstep plant + 1 controller{with_rec} + {label}', max(runs[kind]),
                    'steps/s', 'same run without the live view', base,
                    note=note + '; ratio per round ' + ' '.join(f'{r:.2f}' for r in rounds)))
    return rows


if __name__ == '__main__':
    for r in run('--quick' in sys.argv):
        print(f'{r["name"]}: {r["value"]:.4g} {r["unit"]} | {r["baseline"]}: '
              f'{r["baseline_value"]:.4g} | ratio {r["ratio"]:.3g} | {r["note"]}')
