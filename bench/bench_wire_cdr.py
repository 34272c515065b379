"""
Benchmark of the wire CDR serialiser of a composed run's recorder (pentapod_sim/nodes/wire_cdr.py).

A recorder in a composition gets the per-step messages as rclpy objects and must write the
bytes DDS would deliver (rclpy's ``serialize_message`` leaves padding and tail bytes
uninitialised, so it cannot). rosbags' CDR serialiser writes those bytes; the hand-written
direct path for sensor_msgs/JointState writes the same bytes with ``struct`` and a cached block
of the names. This measures why the direct path exists: messages per second of both on the
plant's strut_states message (15 joints, position and velocity), bytes checked equal.
"""
from __future__ import annotations

from pathlib import Path
import sys
import time

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))                 # run from a checkout
sys.path.insert(0, str(ROOT / 'test'))        # the reference serialiser (rosbags)
from sensor_msgs.msg import JointState  # noqa: E402

from fixtures.rosbags_cdr import RosbagsCdr  # noqa: E402
from pentapod_sim.nodes.wire_cdr import serializer  # noqa: E402


def _messages(n: int) -> list:
    names = [f'strut{i}_{k}' for i in range(1, 6) for k in ('b2', 'b3', 'ax')]
    out = []
    for j in range(n):
        msg = JointState(name=names, position=[1e-6 * (j + i) for i in range(15)],
                         velocity=[1e-3 * (j - i) for i in range(15)])
        msg.header.stamp.sec, msg.header.stamp.nanosec = j // 5000, (j % 5000) * 200_000
        out.append(msg)
    return out


def _rate(serialise, messages) -> float:
    start = time.perf_counter()
    for msg in messages:
        serialise(msg)
    return len(messages) / (time.perf_counter() - start)


def run(quick: bool) -> list[dict]:
    """One row: direct path against rosbags' serialiser, best of 3 alternating."""
    messages = _messages(2000 if quick else 20000)
    direct, library = serializer(JointState), RosbagsCdr(JointState)
    if any(direct(m) != library(m) for m in messages[:200]):
        raise RuntimeError('the direct path and rosbags give different bytes')
    best = {'direct': 0.0, 'rosbags': 0.0}
    for _ in range(3):
        best['direct'] = max(best['direct'], _rate(direct, messages))
        best['rosbags'] = max(best['rosbags'], _rate(library, messages))
    return [{'name': 'wire CDR of a JointState (15 joints), direct path', 'value': best['direct'],
             'unit': 'msg/s', 'baseline': "rosbags' CDR serialiser (same bytes)",
             'baseline_value': best['rosbags'], 'ratio': best['direct'] / best['rosbags'],
             'note': f'{len(messages)} messages, best of 3; what an in-process recorder pays '
                     'per per-step message'}]


if __name__ == '__main__':
    for r in run('--quick' in sys.argv):
        print(f'{r["name"]}: {r["value"]:.4g} {r["unit"]} | {r["baseline"]}: '
              f'{r["baseline_value"]:.4g} | ratio {r["ratio"]:.3g}')
