"""
One study run on the testbed: its scenario with the study's settings, the nodes, the bag.

A run is the scenario (config/scenarios/<name>.yaml, read and checked once) with the study's
typed settings applied to its nodes' typed parameters (position, model file, sample rate,
excitation) and a recorder node added (:func:`study_scenario`). The runner writes it as the
run's one parameter file next to the bag, so every run can be repeated with
``python -m pentapod_sim.scenario.runner <run folder>/scenario.yaml``.
"""
from __future__ import annotations

from dataclasses import dataclass
import logging
import math
import os
from pathlib import Path
import shutil
import time
from typing import Any

import yaml

from pentapod_damper.study.config import StudyConfig
from pentapod_sim import __version__
from pentapod_sim.errors import RunError
from pentapod_sim.interface import EXCITATION, excitation_spec_topic, PMA_STATE, TCP_STATE
from pentapod_sim.registry import PLANT, RECORDER
from pentapod_sim.scenario.files import read_scenario, Scenario
from pentapod_sim.scenario.runner import run_scenario
from pentapod_sim.scenario.warm_start import WarmStarter
from pentapod_sim.sim.periodic_state import PeriodicState, save_initial_state

LOG = logging.getLogger(__name__)

#: Topics every study run records (the strut states are left out: each recorded topic costs
#: the lockstep loop time, and the study's analysis does not need them); the exciter's signal
#: parameters let the analysis find periods and lines in the bag.
RECORDED_TOPICS = [TCP_STATE, EXCITATION, PMA_STATE, excitation_spec_topic('exciter')]
DIRECTIONS = {'x': [1.0, 0.0, 0.0], 'y': [0.0, 1.0, 0.0], 'z': [0.0, 0.0, 1.0]}
#: The composed runs fork from one process that imported the nodes once (its server starts
#: with the first run and ends with this process).
WARM = WarmStarter()


@dataclass
class RunResult:
    """Outcome of one run: where its bag is and how long it took (wall time [s])."""

    name: str
    position: str
    scenario: str
    bag: Path
    params_file: Path
    wall_time: float
    steps: int


def excitation_params(cfg: StudyConfig, kind: str = 'frf') -> dict[str, Any]:
    """
    Exciter parameters of a study run (FRF run or PMA step run).

    An FRF run starts near the loop's periodic steady state
    (:func:`pentapod_damper.study.pipeline.steady_start`): ``cfg.settle_periods`` periods
    (the laws' own fast start transient) are discarded, the ``cfg.periods`` after them
    averaged.
    """
    if kind == 'step':
        return {'kind': 'step', 'amplitude': cfg.step_amplitude,
                'direction': DIRECTIONS[cfg.direction], 'duration': 0.0, 'start_delay': 0.01}
    return {'kind': 'multisine', 'amplitude': cfg.amplitude,
            'direction': DIRECTIONS[cfg.direction], 'f_start': float(cfg.band[0]),
            'f_end': float(cfg.band[1]), 'period': cfg.period, 'phases': 'schroeder',
            'settle_periods': cfg.settle_periods, 'duration': cfg.duration}


def damping_excitation(cfg: StudyConfig, settle: float) -> dict[str, Any]:
    """
    Exciter parameters of a damping run: Schroeder multisine, settled ``settle`` s or more.

    The settling time is rounded up to whole periods (``settle_periods``); then
    ``cfg.damping_periods`` periods follow, which the analysis averages.
    """
    period = cfg.damping_period
    settle_periods = max(1, math.ceil(settle / period - 1e-9))
    return {'kind': 'multisine', 'amplitude': cfg.damping_amplitude,
            'direction': DIRECTIONS[cfg.direction], 'f_start': float(cfg.damping_band[0]),
            'f_end': float(cfg.damping_band[1]), 'period': period, 'phases': 'schroeder',
            'settle_periods': settle_periods,
            'duration': (settle_periods + cfg.damping_periods) * period}


def study_scenario(scenario: str, position: str, model_file: Path, cfg: StudyConfig,
                   bag_dir: Path, run_info: dict[str, Any], kind: str = 'frf',
                   exciter: dict[str, Any] | None = None,
                   initial_state: Path | None = None) -> Scenario:
    """
    One run: the scenario's nodes with the study settings, and a recorder (typed, checked).

    Every node at the study's sample rate; ``exciter`` replaces the exciter parameters of
    ``kind`` (damping runs), and the run then lasts the exciter's ``duration``. The
    scenario's own recorders are replaced by the run's, which every node waits for. The plant
    starts from the state in the file ``initial_state`` if given, else from rest.
    """
    base = read_scenario(scenario)
    run = base.without(n.name for n in base.of_role(RECORDER) if n.name != 'recorder')
    duration = run_duration(cfg, kind, exciter)
    for node in run.nodes:
        changes: dict[str, Any] = {}
        if hasattr(node.params, 'sample_rate'):
            changes['sample_rate'] = cfg.sample_rate
        if hasattr(node.params, 'wait_for_subscribers'):
            # nothing is published before the recorder is matched (plant: step 0; sources:
            # their first answer), so the bag holds every step
            changes['wait_for_subscribers'] = ['recorder']
        if node.role == PLANT:
            # the study checks every loop against its check model itself
            # (pipeline.scenario_analytic): the plant's start-up check would repeat it
            changes.update(position=position, model_file=str(model_file), duration=duration,
                           timing='lockstep', steps=0, output_file='', loop_check='off',
                           # the waited-for recorder gets every step even if it matches late
                           # (transient-local per-step writers; in a composition the hand-off)
                           subscriber_settle=0.0,
                           initial_state_file=str(initial_state) if initial_state else '')
        if node.role == RECORDER:
            continue                              # replaced below
        if node.kind == 'exciter':
            signal = dict(exciter) if exciter else excitation_params(cfg, kind)
            run = run.with_node(node.name, {**signal, **changes})
        else:
            run = run.with_params(node.name, **changes)
    info = dict(run_info, scenario_parameters={   # the nodes' sections, as run
        name: {'ros__parameters': section} for name, section in run.sections.items()})
    return run.with_node('recorder', {
        'topics': RECORDED_TOPICS, 'output_dir': str(bag_dir.parent), 'bag_name': bag_dir.name,
        'run_info': yaml.safe_dump(info, sort_keys=False)})


def run_duration(cfg: StudyConfig, kind: str, exciter: dict[str, Any] | None = None) -> float:
    """Simulated time of a run [s]: the exciter's duration if given, else the study's."""
    if exciter:
        return float(exciter['duration'])
    return cfg.duration if kind == 'frf' else cfg.step_duration


def run_on_testbed(scenario: str, position: str, model_file: Path, model_hash: str,
                   cfg: StudyConfig, out_dir: Path, kind: str = 'frf',
                   timeout: float = 900.0, exciter: dict[str, Any] | None = None,
                   composed: bool = True,
                   initial_state: PeriodicState | None = None) -> RunResult:
    """
    Run one scenario at one position in lockstep and record it.

    ``composed`` (default) runs every node in one process on one executor
    (:mod:`pentapod_sim.nodes.composed`), forked from :data:`WARM`: the same node classes
    and, bit for bit, the same run as separate processes, but faster. ``initial_state``: the
    plant's state at step 0 (written to ``initial_state.npz`` in the run's folder and named
    in the bag's metadata), else rest.

    Raises
    ------
    RunError
        If a node fails or the bag is missing; the message names the run and its log folder.
    """
    # a shipped scenario's name, or a scenario file (named after its file)
    name = f'{position}_{Path(scenario).stem}' + ('' if kind == 'frf' else f'_{kind}')
    run_dir = out_dir / 'runs' / name
    bag_dir = run_dir / 'bag'
    run_dir.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(bag_dir, ignore_errors=True)   # a bag of an earlier run of this name
    info = {'study_run': name, 'scenario': scenario, 'position': position,
            'excitation': kind, 'model_file': str(model_file), 'model_hash': model_hash,
            'sample_rate': cfg.sample_rate, 'package_version': __version__,
            'initial_state': 'rest' if initial_state is None else
            'periodic steady state of the linear loop (plant state; laws from zero)'}
    x0_file = (None if initial_state is None else
               save_initial_state(run_dir / 'initial_state.npz', initial_state))
    run = study_scenario(scenario, position, model_file, cfg, bag_dir, info, kind, exciter,
                         x0_file)
    params_file = run_dir / 'scenario.yaml'
    env = dict(os.environ, ROS_LOG_DIR=str(run_dir / 'ros_log'))
    t0 = time.perf_counter()
    code = run_scenario(run, {}, timeout, env, log_dir=run_dir / 'logs', composed=composed,
                        warm=WARM, params_file=params_file)
    wall = time.perf_counter() - t0
    if code != 0:
        errors = [line.strip() for log in sorted((run_dir / 'logs').glob('*.log'))
                  for line in log.read_text(errors='replace').splitlines()
                  if line.startswith('error:')]
        raise RunError(f'run {name} failed (exit code {code}): {"; ".join(errors) or "?"}; '
                       f'parameters in {params_file}, node logs in {run_dir / "logs"}')
    if not (bag_dir / 'metadata.yaml').is_file():
        raise RunError(f'run {name}: the recorder left no complete bag in {bag_dir}')
    steps = int(round(run_duration(cfg, kind, exciter) * cfg.sample_rate))
    LOG.info('run %s: %d steps in %.1f s wall time (%.0f steps/s)', name, steps, wall,
             steps / wall)
    return RunResult(name, position, scenario, bag_dir, params_file, wall, steps)
