"""
The judge's runs: recorded lockstep ROS 2 runs of plant, excitation, controller and recorder.

Two kinds per position and controller (the baseline runs the first kind only):

* **multisine** (one per judged TCP direction): a Schroeder multisine at the TCP
  (:func:`exciter_params`), settled and then averaged over whole periods; it gives the
  compliance, the damping per mode, the actuator demand and the machining verdict;
* **robustness**: independent white noise on every port the controller answers and on the
  collocated inputs of the sensors it reads (the ``disturbance`` node), no exciter; it gives
  the controller's own FRF for the loop check.

Each run is a scenario file written to its run folder (``scenario.yaml``: run it again with
``scenario <run folder>/scenario.yaml``), started by the scenario runner, composed when the
controller allows it; its bag is ``<run folder>/bag``. Runs of the baseline and of the shipped
laws do not change between judgements of different controllers: they are kept under
``out/judge/runs`` by a hash of their scenario and the plant, and a later judgement reuses them
(``--fresh`` runs them again).
"""
from __future__ import annotations

from dataclasses import dataclass
import hashlib
import json
import logging
import math
import os
from pathlib import Path
import shutil
import signal
import subprocess
import time
from typing import Any, Callable

import numpy as np
import yaml

from pentapod_damper.judge.config import JudgeConfig
from pentapod_damper.judge.controller import Controller
from pentapod_damper.judge.models import PositionModel
from pentapod_sim import __version__, registry, shutdown
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.interface import (
    controller_model_topic,
    EXCITATION,
    excitation_spec_topic,
    force_topic,
    PMA_STATE,
    port_location,
    RUN_STATUS,
    STATE_TOPICS,
    TCP_STATE,
)
from pentapod_sim.parameters import declares, load_class, NODE_CLASS, NodeParams, params_of
from pentapod_sim.plant.ports import collocated_input_of, collocated_output
from pentapod_sim.scenario.domain import DOMAIN_VAR, isolated_env
from pentapod_sim.scenario.files import dump_params
from pentapod_sim.scenario.runner import run_scenario
from pentapod_sim.scenario.warm_start import WarmStarter

LOG = logging.getLogger(__name__)

MULTISINE, ROBUSTNESS = 'multisine', 'robustness'
DIRECTIONS = {'x': [1.0, 0.0, 0.0], 'y': [0.0, 1.0, 0.0], 'z': [0.0, 0.0, 1.0]}
#: Wall time [s] a run takes besides its steps (start-up and drain), for the time left.
START_UP = 8.0
#: Steps per second assumed for the time left before a run of that kind was measured.
GUESS_RATE = {True: 1500.0, False: 700.0}


@dataclass(frozen=True)
class RunSpec:
    """One planned run."""

    position: str
    controller: Controller
    kind: str
    direction: str          # '' for a robustness run
    steps: int

    @property
    def name(self) -> str:
        """``P1_baseline_multisine_x``."""
        tail = f'_{self.direction}' if self.direction else ''
        return f'{self.position}_{self.controller.slug}_{self.kind}{tail}'


@dataclass(frozen=True)
class RunRecord:
    """A finished run: where its bag is, how long it took, whether it was reused."""

    spec: RunSpec
    bag: Path
    scenario_file: Path
    wall_time: float
    reused: bool
    failed: str = ''        # why the run ended early (a controller's run only), '' if it did not


def settle_time(plant: Any, direction: str, band: tuple[float, ...], count: int) -> float:
    """
    Decay time 1 / (zeta omega) [s] of the slowest of the ``count`` strongest open-loop modes.

    Strongest: the largest peaks ``|c_d,i b_i| / (2 zeta_i omega_i^2)`` of the modes' terms in
    TCP displacement / force along ``direction``, among the modes in ``band``.
    """
    out = plant.output_names.index(f'tcp_displacement_{direction}')
    inp = plant.input_names.index(f'tcp_force_{direction}')
    omega, zeta = plant.omega, plant.zeta
    peak = np.abs(plant.c_disp[out] * plant.b[:, inp]) / (2 * zeta * omega ** 2)
    f = plant.frequencies_hz
    cand = np.flatnonzero((f >= band[0]) & (f <= band[1]))
    top = cand[np.argsort(-peak[cand])][:count]
    return float(np.max(1.0 / (zeta[top] * omega[top]), initial=0.0))


def settle_periods(cfg: JudgeConfig, pos: PositionModel) -> int:
    """Settling periods of every multisine run at a position (from the baseline's modes)."""
    ms = cfg.multisine
    slowest = max(settle_time(pos.plant, d, ms.band, ms.settle_modes) for d in cfg.directions)
    return max(1, math.ceil(ms.time_constants * slowest / ms.period - 1e-9))


def exciter_params(cfg: JudgeConfig, direction: str, settle: int) -> dict[str, Any]:
    """The exciter's section of a multisine run."""
    ms = cfg.multisine
    return {'kind': 'multisine', 'amplitude': ms.amplitude, 'direction': DIRECTIONS[direction],
            'f_start': float(ms.band[0]), 'f_end': float(ms.band[1]), 'period': ms.period,
            'phases': 'schroeder', 'settle_periods': settle,
            'duration': (settle + ms.periods) * ms.period}


def disturbance_ports(ports: tuple[str, ...], sensors: tuple[str, ...]) -> list[str]:
    """The controller's ports and the collocated inputs of its sensors, each once."""
    out = list(ports)
    for sensor in sensors:
        near = collocated_input_of(sensor)
        if near not in out:
            out.append(near)
    return out


def recorded_topics(ctrl: Controller, kind: str, ports: tuple[str, ...],
                    sensors: tuple[str, ...]) -> list[str]:
    """Topics a run records: excitation, TCP, the controller's answers, models and outputs."""
    topics = [TCP_STATE, RUN_STATUS] + ([EXCITATION, excitation_spec_topic('exciter'), PMA_STATE]
                            if kind == MULTISINE else [force_topic('disturbance')])
    for source in ctrl.sources:
        topics += [force_topic(source), controller_model_topic(source)]
    if ctrl.sources:
        if ports:
            outputs = [collocated_output(p) for p in ports] + list(sensors)
            topics += [port_location(o)[0] for o in outputs]
        else:                              # not known yet: every state topic
            topics += list(STATE_TOPICS)
    return list(dict.fromkeys(topics))


def _declares(section: dict[str, Any], name: str, node: str) -> bool:
    target = section.get(NODE_CLASS)
    if target is None or ':' not in str(target):
        kind = target or next((k.name for k in sorted(registry.NODES, key=lambda k: -len(k.name))
                               if node.startswith(k.name)), None)
        return kind is not None and declares(params_of(str(kind)), name)
    schema = getattr(load_class(str(target)), 'Params', None)
    return isinstance(schema, type) and issubclass(schema, NodeParams) and declares(schema, name)


def run_document(spec: RunSpec, cfg: JudgeConfig, pos: PositionModel, settle: int,
                 ports: tuple[str, ...], sensors: tuple[str, ...], bag_dir: Path,
                 run_info: dict[str, Any]) -> dict[str, Any]:
    """The scenario file of one run (a ROS 2 parameter file)."""
    ctrl = spec.controller
    doc: dict[str, Any] = {'/**': {'ros__parameters': {'sample_rate': cfg.sample_rate}}}
    plant: dict[str, Any] = {
        'model_file': str(pos.model_file), 'steps': spec.steps, 'timing': 'lockstep',
        'loop_check': 'off', 'output_file': '', 'wait_for_subscribers': ['recorder'],
        'subscriber_settle': 0.0, 'startup_timeout': 120.0 if not ctrl.composed else 60.0}
    if spec.kind == MULTISINE:
        source = 'exciter'
        doc[source] = {'ros__parameters': {
            **exciter_params(cfg, spec.direction, settle), 'wait_for_subscribers': ['recorder']}}
    else:
        source = 'disturbance'
        noise = disturbance_ports(ports, sensors)
        doc[source] = {'ros__parameters': {
            'ports': noise, 'amplitude': cfg.robustness.amplitude, 'seed': 1,
            'wait_for_subscribers': ['recorder']}}
        plant['source_ports'] = {source: noise}
    for name, section in ctrl.nodes.items():
        values = dict(section)
        if _declares(section, 'wait_for_subscribers', name):
            values['wait_for_subscribers'] = ['recorder']
        doc[name] = {'ros__parameters': values}
    plant['sources'] = [source, *ctrl.sources]
    if ports and len(ctrl.sources) == 1:
        plant.setdefault('source_ports', {})[ctrl.sources[0]] = list(ports)
    doc['plant'] = {'ros__parameters': plant}
    doc['recorder'] = {'ros__parameters': {
        'topics': recorded_topics(ctrl, spec.kind, ports, sensors),
        'output_dir': str(bag_dir.parent), 'bag_name': bag_dir.name,
        'run_info': yaml.safe_dump(run_info, sort_keys=False)}}
    if ctrl.how == 'node':     # it outlives the runs: its writer holds the earlier runs' steps
        doc['recorder']['ros__parameters']['fresh_topics'] = [force_topic(s)
                                                              for s in ctrl.sources]
    return doc


def reusable(ctrl: Controller) -> bool:
    """Runs that depend on shipped code and files only (the baseline, shipped laws)."""
    return ctrl.how == 'baseline' or (ctrl.how == 'scenario' and all(
        ':' not in str(s.get(NODE_CLASS, '')) for s in ctrl.nodes.values()))


def run_key(doc: dict[str, Any], pos: PositionModel) -> str:
    """Hash of a run's scenario (without its bag's place) and plant."""
    plain = json.loads(json.dumps(doc))
    plain['recorder']['ros__parameters'].pop('output_dir')
    plain['recorder']['ros__parameters'].pop('bag_name')
    plain['recorder']['ros__parameters'].pop('run_info')
    plain['plant']['ros__parameters'].pop('model_file')
    text = json.dumps([plain, pos.plant.content_hash(), __version__], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


class Runner:
    """Starts the runs one after the other and says how many are left and for how long."""

    def __init__(self, out_dir: Path, plan: list[RunSpec], fresh: bool = False,
                 say: Callable[[str], None] = print) -> None:
        self.out_dir = out_dir
        self.plan = list(plan)
        self.fresh = fresh
        self.say = say
        self.done = 0
        # steps per second of each controller's long runs (speeds differ tenfold: a law on the
        # in-process hand-off against a plain node answering over DDS)
        self.rate: dict[str, list[float]] = {}
        self.warm = WarmStarter()

    def left(self) -> str:
        """``8 runs left, about 9 min``."""
        todo = self.plan[self.done:]
        seconds = 0.0
        for spec in todo:
            rates = self.rate.get(spec.controller.label, [])
            rate = float(np.median(rates)) if rates else GUESS_RATE[spec.controller.composed]
            seconds += spec.steps / rate + START_UP
        return (f'{len(todo)} run{"s" * (len(todo) != 1)} left, about '
                f'{seconds / 60:.0f} min' if todo else 'no run left')

    def run(self, spec: RunSpec, doc: dict[str, Any], pos: PositionModel) -> RunRecord:
        """Run (or reuse) one planned run; RunError names the run and its logs."""
        reuse = reusable(spec.controller) and not self.fresh
        key = run_key(doc, pos)
        folder = self.out_dir / 'runs' / (f'{spec.name}_{key}' if reuse else spec.name)
        bag = folder / 'bag'
        done = folder / 'done.json'
        index = self.plan.index(spec) + 1
        if reuse and done.is_file() and (bag / 'metadata.yaml').is_file():
            self.done += 1
            wall = float(json.loads(done.read_text())['wall_time'])
            self.say(f'run {index}/{len(self.plan)} {spec.name}: recorded before, reused '
                     f'({folder}); {self.left()}')
            return RunRecord(spec, bag, folder / 'scenario.yaml', wall, True)
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        doc['recorder']['ros__parameters'].update(output_dir=str(folder), bag_name='bag')
        path = folder / 'scenario.yaml'
        path.write_text(dump_params(doc), encoding='utf-8')
        self.say(f'run {index}/{len(self.plan)} {spec.name}: {spec.steps} steps '
                 f'({"composed" if spec.controller.composed else "separate processes"}) ...')
        t0 = time.perf_counter()
        code = self._start(spec.controller, path, folder, spec.steps)
        wall = time.perf_counter() - t0
        has_bag = (bag / 'metadata.yaml').is_file()
        if code != 0:
            why = (f'run {spec.name} failed (exit code {code}): {_errors(folder)}; '
                   f'scenario {path}, node logs in {folder / "logs"}')
            if spec.controller.how == 'baseline' or not has_bag or shutdown.requested():
                raise RunError(why)
            # the controller's fault (an unstable loop, efforts over the plant's limit, a
            # silent node): a verdict, not an error; its bag shows what happened until then
            self.done += 1
            self.say(f'run {index}/{len(self.plan)} {spec.name}: ended early: {_errors(folder)}'
                     f'; {self.left()}')
            return RunRecord(spec, bag, path, wall, False, _errors(folder))
        if not has_bag:
            raise RunError(f'run {spec.name}: the recorder left no complete bag in {bag}')
        done.write_text(json.dumps({'wall_time': wall, 'steps': spec.steps}))
        self.done += 1
        if wall > 4 * START_UP:                 # short runs measure the start-up only
            self.rate.setdefault(spec.controller.label, []).append(
                spec.steps / (wall - START_UP))
        self.say(f'run {index}/{len(self.plan)} {spec.name}: {wall:.1f} s '
                 f'({spec.steps / wall:.0f} steps/s); {self.left()}')
        return RunRecord(spec, bag, path, wall, False)

    def _start(self, ctrl: Controller, path: Path, folder: Path, steps: int) -> int:
        env = dict(os.environ, ROS_LOG_DIR=str(folder / 'ros_log'))
        timeout = 600.0 + steps / 100.0
        logs = folder / 'logs'
        if ctrl.how == 'node':
            env.setdefault(DOMAIN_VAR, '0')           # where `ros2 run` started it
        if ctrl.how != 'command':
            return run_scenario(path, {}, timeout, env, log_dir=logs, composed=ctrl.composed,
                                warm=self.warm if ctrl.composed else None)
        with isolated_env(env) as run_env:
            logs.mkdir(parents=True, exist_ok=True)
            with open(logs / 'command.log', 'w') as log:
                proc = subprocess.Popen(list(ctrl.command), env=run_env, stdout=log,
                                        stderr=subprocess.STDOUT,
                                        preexec_fn=shutdown.die_with_parent)
                try:
                    code = run_scenario(path, {}, timeout, run_env, log_dir=logs)
                finally:
                    _stop(proc)
        if proc.returncode not in (0, -signal.SIGINT, 128 + signal.SIGINT) and code == 0:
            LOG.warning('the controller command ended with exit code %s (%s)', proc.returncode,
                        logs / 'command.log')
        return code


def _stop(proc: subprocess.Popen[bytes]) -> None:
    """SIGINT, then SIGKILL after 5 s."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _errors(folder: Path) -> str:
    lines = [line.strip() for log in sorted((folder / 'logs').glob('*.log'))
             for line in log.read_text(errors='replace').splitlines()
             if line.startswith('error:') or ' ERROR ' in line or '[ERROR]' in line]
    return '; '.join(lines[:5]) or 'see the node logs'


def check_positions(names: tuple[str, ...], known: list[str]) -> None:
    """ConfigError for a position name that config/positions.yaml lacks."""
    for name in names:
        if name not in known:
            raise ConfigError(f'no position {name!r} in config/positions.yaml (known: '
                              f'{", ".join(known)})')
