"""
What a bag says about its run (ROS-free).

The plant's run status, the recorder's counts, the linear models the sources published, and
how the steps of a per-step topic were answered.

* :func:`run_statuses`: every ``/pentapod/run_status`` message (diagnostic_msgs/DiagnosticStatus)
  as its key/value mapping, in order; the last one holds ``state`` (finished or stopped),
  ``steps`` and ``rejected_messages`` (force messages the plant rejected, every source and
  reason, docs/recording.md).
* :func:`recording_report`: the recorder's expected, recorded and missing messages per topic
  (MCAP metadata record ``pentapod_recording``).
* :func:`controller_models`: the text each source published on
  ``/pentapod/controller_models/<source>`` (a JSON model, ``no feedback`` or ``no linear
  model: ...``).
* :func:`step_answers`: per-step topic counts: unique steps, repeats of a step (a re-sent
  step or answer), and steps absent between the first and the last.
"""
from __future__ import annotations

from dataclasses import dataclass
import struct
from typing import Any

import numpy as np
import yaml

from pentapod_sim.analysis.bag.excitation_record import string_of
from pentapod_sim.analysis.bag.reader import Bag
from pentapod_sim.errors import BagError
from pentapod_sim.interface import CONTROLLER_MODEL_PREFIX, RUN_STATUS

#: Name of the recorder's MCAP metadata record (pentapod_sim.nodes.recorder_node).
RECORDING_RECORD = 'pentapod_recording'


def _string(body: bytes, off: int, order: str) -> tuple[str, int]:
    off += (-off) % 4
    (length,) = struct.unpack_from(order + 'I', body, off)
    if length < 1 or off + 4 + length > len(body):
        raise BagError(f'run status: a string of {length} bytes at offset {off} overruns the '
                       f'message ({len(body)} bytes)')
    return bytes(body[off + 4:off + 3 + length]).decode('utf-8'), off + 4 + length


def status_values(payload: bytes) -> dict[str, str]:
    """Key/value pairs of one CDR-serialised diagnostic_msgs/DiagnosticStatus."""
    if len(payload) < 8 or payload[1] not in (0, 1):
        raise BagError(f'not a CDR DiagnosticStatus ({len(payload)} bytes)')
    order = '<' if payload[1] == 1 else '>'
    body = bytes(payload[4:])
    off = 1                                             # byte level
    for _ in range(3):                                  # name, message, hardware_id
        _, off = _string(body, off, order)
    off += (-off) % 4
    (count,) = struct.unpack_from(order + 'I', body, off)
    off += 4
    values = {}
    for _ in range(count):
        key, off = _string(body, off, order)
        value, off = _string(body, off, order)
        values[key] = value
    return values


def run_statuses(bag: Bag) -> list[dict[str, str]]:
    """Every run-status message of the bag, in recorded order (empty if none)."""
    if RUN_STATUS not in bag.topics:
        return []
    data = bag.topic(RUN_STATUS)
    order = np.argsort(data.log_time_ns, kind='stable')
    return [status_values(data.payloads[int(i)]) for i in order]


def recording_report(bag: Bag) -> dict[str, dict[str, int]]:
    """
    The recorder's counts: ``{'expected': {topic: n}, 'recorded': {...}, 'missing': {...}}``.

    Empty mappings if the bag has no report (a recorder stopped before it wrote one).
    """
    record = bag.mcap_metadata.get(RECORDING_RECORD, {})
    out: dict[str, dict[str, int]] = {}
    for key in ('expected', 'recorded', 'missing'):
        try:
            value: Any = yaml.safe_load(record.get(key, '{}')) or {}
        except yaml.YAMLError:
            value = {}
        out[key] = {str(t): int(n) for t, n in value.items()} if isinstance(value, dict) else {}
    return out


def controller_models(bag: Bag) -> dict[str, str]:
    """``{source: text}`` of the models the sources published (the last message of each)."""
    out = {}
    for topic, data in bag.topics.items():
        if topic.startswith(CONTROLLER_MODEL_PREFIX) and data.count:
            out[topic.removeprefix(CONTROLLER_MODEL_PREFIX)] = string_of(
                data.payloads[data.count - 1])
    return out


@dataclass(frozen=True)
class StepAnswers:
    """How the steps of one per-step topic were recorded."""

    messages: int
    unique_steps: int
    repeats: int            # messages for a step already recorded (re-sent steps or answers)
    gaps: int               # steps absent between the first and the last recorded one


def step_answers(bag: Bag, topic: str, dt: float) -> StepAnswers:
    """Counts of a per-step topic whose messages carry the step's stamp (JointState)."""
    if topic not in bag.topics:
        return StepAnswers(0, 0, 0, 0)
    steps = np.rint(bag.times_ns(topic) / (dt * 1e9)).astype(np.int64)
    unique = np.unique(steps)
    gaps = int(unique[-1] - unique[0] + 1 - unique.size) if unique.size else 0
    return StepAnswers(int(steps.size), int(unique.size), int(steps.size - unique.size), gaps)
