"""
A scenario's machine cutting: its laws, a cutting node instead of the exciter, a recorder.

:func:`cutting_scenario` turns a scenario (its plant and damping nodes) into a cutting run: the
exciters and recorders go, a cutting node with the given parameters joins the plant's sources
at the plant's sample rate, the plant runs for the given time and a recorder writes the topics
``analyze chatter`` needs. :func:`record_cut` runs such a scenario composed (optionally forked
warm, as the study's runs are), reads the bag back and judges it: a :class:`RecordedCut`, the
time-domain check of a predicted limit (:func:`pentapod_sim.machining.loop_lobes.check_runs`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
import shutil
import time
from typing import Any, Mapping

from pentapod_sim.analysis.bag.cutting_record import chatter_of, cut_record, CUTTING_TOPICS
from pentapod_sim.errors import RunError
from pentapod_sim.interface import force_topic
from pentapod_sim.machining.chatter import ChatterVerdict
from pentapod_sim.machining.loop_lobes import CuttingRun
from pentapod_sim.registry import RECORDER
from pentapod_sim.scenario.files import read_scenario, Scenario
from pentapod_sim.scenario.runner import run_scenario
from pentapod_sim.scenario.warm_start import WarmStarter

#: Node name of the cutting node a cutting run adds (and of its force topic).
CUTTING = 'cutting'
#: Node name of the recorder a cutting run adds.
RECORDER_NAME = 'recorder'
#: Topics a cutting run records: what ``analyze chatter`` reads, and the cutting force.
RECORDED = [*CUTTING_TOPICS, force_topic(CUTTING)]


def cutting_scenario(scenario: str | Path | Scenario, cutting: Mapping[str, Any],
                     duration: float, bag_dir: Path, model_file: str = '',
                     position: str = '') -> Scenario:
    """
    The scenario's plant and laws with a cutting node and a recorder (module docstring).

    Parameters
    ----------
    scenario : str, Path or Scenario
        A shipped scenario's name, a file or a parsed scenario.
    cutting : mapping
        Cutting node parameters (operation, spindle_speed, axial_depth, overrides).
    duration : float
        Simulated time [s].
    bag_dir : Path
        The bag folder the recorder writes (its parent is created by the recorder).
    model_file, position : str
        The plant's model file, or its position (the scenario's if both are empty).
    """
    base = read_scenario(scenario)
    drop = [n.name for n in base.nodes
            if n.kind in ('exciter', CUTTING) or n.role == RECORDER]
    run = base.without(drop)
    plant = run.plant.params
    sources = [s for s in plant.sources if s not in drop] + [CUTTING]
    run = run.with_node(CUTTING, {**cutting, 'sample_rate': plant.sample_rate,
                                  'wait_for_subscribers': [RECORDER_NAME]})
    changes: dict[str, Any] = {'sources': sources, 'duration': float(duration), 'steps': 0,
                               'timing': 'lockstep', 'output_file': '',
                               'wait_for_subscribers': [RECORDER_NAME]}
    if 'source_ports' in run.plant.given:
        changes['source_ports'] = {k: v for k, v in plant.source_ports.items() if k in sources}
    if model_file or position:
        changes.update(model_file=str(model_file), position=position or plant.position)
    run = run.with_params(run.plant.name, **changes)
    return run.with_node(RECORDER_NAME, {'topics': RECORDED, 'output_dir': str(bag_dir.parent),
                                         'bag_name': bag_dir.name})


@dataclass(frozen=True)
class RecordedCut:
    """A recorded cutting run and its verdict; ``wall_time`` [s] of the whole run."""

    run: CuttingRun
    bag: Path
    verdict: ChatterVerdict
    wall_time: float

    @property
    def as_expected(self) -> bool:
        """True if a run below the limit is stable and one above it chatters."""
        return self.verdict.is_chatter == (self.run.expected == 'chatter')


def record_cut(scenario: str | Path | Scenario, run: CuttingRun, bag_dir: Path,
               model_file: str = '', position: str = '', warm: WarmStarter | None = None,
               timeout: float = 3600.0) -> RecordedCut:
    """
    Run one cutting run composed, record it, judge the bag (``run.settle`` left out).

    Raises
    ------
    RunError
        If the run fails (the message names the log folder) or leaves no bag.
    """
    bag_dir = Path(bag_dir)
    shutil.rmtree(bag_dir, ignore_errors=True)
    bag_dir.parent.mkdir(parents=True, exist_ok=True)
    checked = cutting_scenario(scenario, run.params, run.duration, bag_dir, model_file,
                               position)
    logs = bag_dir.parent / f'{bag_dir.name}_logs'
    t0 = time.perf_counter()
    code = run_scenario(checked, {}, timeout, log_dir=logs, composed=True, warm=warm,
                        params_file=bag_dir.parent / f'{bag_dir.name}.yaml')
    wall = time.perf_counter() - t0
    if code != 0 or not (bag_dir / 'metadata.yaml').is_file():
        raise RunError(f'cutting run {bag_dir.name} failed (exit code {code}); node logs in '
                       f'{logs}')
    return RecordedCut(run, bag_dir, chatter_of(cut_record(bag_dir), run.settle), wall)
