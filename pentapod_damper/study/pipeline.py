"""
Steps of the study: plant models, analytic FRFs, testbed runs, and what is measured from them.

ROS appears only through :func:`pentapod_damper.study.runs.run_on_testbed`, which starts node
processes; everything here reads and computes plain arrays.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
from pathlib import Path
import threading
from typing import Any, Callable

import numpy as np

from pentapod_damper.node_parameters import PmaParams
from pentapod_damper.scenario_laws import scenario_laws, viscous_equivalent
from pentapod_damper.study.analytic import (
    continuous_frf,
    discrete_frf,
    DiscreteFrf,
    pma_requirements,
    sampled_loop,
)
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.damping import continuous_loop_frf
from pentapod_damper.study.pma import pma_design, PmaDesign
from pentapod_damper.study.records import (
    ComplexArray,
    FloatArray,
    Measured,
    PmaSpec,
    PositionModel,
    ScenarioAnalytic,
)
from pentapod_damper.study.runs import excitation_params, RunResult
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.analysis.frf.from_run import frfs_from_bag
from pentapod_sim.analysis.frf.periodic import synchronous_frf
from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.imported.build import load_fe_model
from pentapod_sim.interface import EXCITATION, PMA_STATE, TCP_STATE
from pentapod_sim.plant.build import build_plant, plant_from_fe, reduce_plant
from pentapod_sim.plant.check_model import (
    check_f_max,
    check_model_from_fe,
    load_or_build_check_model,
)
from pentapod_sim.plant.config import load_reduction_config
from pentapod_sim.plant.drives import DriveSet, with_drives
from pentapod_sim.plant.frf_peaks import exact_peak, plant_pair_frf
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.scenario.laws import scenario_drives
from pentapod_sim.sim.controllers import controller_of, LoopSystem
from pentapod_sim.sim.excitation import Excitation, ExcitationSpec
from pentapod_sim.sim.periodic_state import (
    periodic_state,
    PeriodicState,
    start_with_laws_at_rest,
)
from pentapod_sim.sim.stability import apply_policy, check_loop, LoopCheck

LOG = logging.getLogger(__name__)


#: Cache of check models (shared with the plant node's default model cache).
CHECK_CACHE = Path('out') / 'models'


def prepare_model(position: str, out_dir: Path, say: Callable[[str], None],
                  cfg: StudyConfig | None = None,
                  fe_model: Path | None = None) -> PositionModel:
    """
    Build the reduced plant of a position and save it (the plant node loads the file).

    With ``cfg``, also load or build the position's check model (modes below
    ``max(check_f_min, 2 sample_rate)``, cached in :data:`CHECK_CACHE`). ``fe_model``: an
    imported FE model's description (docs/own_machine.md) instead of the own machine at
    ``position``, which then only names the model; its check model is built, not cached.
    """
    check = None
    if fe_model is None:
        plant = build_plant(position, progress=say)
        if cfg is not None:
            check, origin = load_or_build_check_model(
                position, check_f_max(cfg.sample_rate, cfg.check_f_min), CHECK_CACHE)
            say(f'check model {origin}: {check.n_modes} modes')
    else:
        fe = load_fe_model(fe_model)
        reduction = load_reduction_config()
        plant_all, keep = plant_from_fe(fe, reduction, say)
        plant = reduce_plant(plant_all, keep, reduction.static_correction)
        plant.meta['position'] = position
        say(f'imported from {fe_model}: kept {keep.size} of {plant_all.n_modes} modes')
        if cfg is not None:
            f_max = check_f_max(cfg.sample_rate, cfg.check_f_min)
            check = check_model_from_fe(fe, reduction, f_max)
            say(f'check model built from {fe_model} (modes below {f_max:g} Hz): '
                f'{check.n_modes} modes')
    path = plant.save(out_dir / 'models' / f'plant_{position}.npz')
    return PositionModel(position, plant, Path(path), plant.content_hash(), check)


def frf_excitation(cfg: StudyConfig) -> Excitation:
    """The FRF runs' multisine, sample for sample as the exciter node builds it."""
    return Excitation(ExcitationSpec(**excitation_params(cfg)), cfg.dt)


def line_freq(cfg: StudyConfig) -> FloatArray:
    """The FRF runs' excited lines [Hz] (multiples of 1 / period in the band)."""
    return np.asarray(frf_excitation(cfg).lines_hz, dtype=np.float64)


def steady_start(cfg: StudyConfig, ana: ScenarioAnalytic,
                 exciter: dict[str, Any] | None = None) -> PeriodicState:
    """
    The periodic steady state of the scenario's sampled loop under a run's multisine.

    ``exciter``: the run's exciter parameters (default: the FRF runs', :func:`frf_excitation`).

    From the linear models of plant and laws (:attr:`ScenarioAnalytic.sampled`). The laws'
    nodes start at rest, so the plant starts shifted from its periodic state such that the
    laws' zero start excites only the loop's fastest modes (their filters'), not the lightly
    damped ones (:func:`pentapod_sim.sim.periodic_state.start_with_laws_at_rest`).
    """
    exc = (frf_excitation(cfg) if exciter is None
           else Excitation(ExcitationSpec(**exciter), cfg.dt))
    loop = ana.sampled
    assert exc.period_steps is not None and loop is not None
    forces = exc.series(exc.period_steps)
    ports = loop.core.input_names
    e = np.zeros((exc.period_steps, len(ports)))
    for i, axis in enumerate('xyz'):
        e[:, ports.index(f'tcp_force_{axis}')] = forces[:, i]
    system = LoopSystem(loop.a, loop.b, loop.c_y, loop.c_u, loop.augmented)
    return start_with_laws_at_rest(system, loop.core.n_states,
                                   periodic_state(system, loop.core.n_states, e))


def scenario_pma(scenario: str) -> PmaSpec | None:
    """The proof-mass actuator of a scenario file (its PMA node), if any."""
    for node in read_scenario(scenario).of_kind('pma'):
        values: PmaParams = node.params           # typed, with the PMA node's defaults
        return PmaSpec(values.proof_mass, values.gain, values.directions)
    return None


def scenario_analytic(model: PositionModel, scenario: str, cfg: StudyConfig,
                      freq: FloatArray) -> ScenarioAnalytic:
    """
    Closed-loop FRFs of a scenario from the TCP force, its exact peak and truncation check.

    The continuous FRF is evaluated on ``freq``, and its peak over [band[0], f_max] searched
    at the resonances (:func:`pentapod_sim.plant.frf_peaks.exact_peak`); the sampled-loop FRF
    at the lines of the FRF runs' multisine (:func:`line_freq`), so both compare line by line.
    The sampled loop is checked on the plant and the check model
    (:func:`pentapod_sim.sim.stability.check_loop`, policy ``cfg.check_policy``); a loop
    unstable on the plant itself is refused whatever the policy.
    """
    d = cfg.direction
    dt = cfg.dt
    parsed = read_scenario(scenario)
    laws = scenario_laws(parsed.sections, dt)
    dampers = viscous_equivalent(laws)
    drives = scenario_drives(parsed)
    plant = with_drives(model.plant, drives)
    loop = checked_loop(model, [controller_of(law) for law in laws], dt, cfg.check_policy,
                        f'scenario {scenario} at {model.position}', drives)
    if loop.plant_radius >= 1.0:       # whatever the policy: the run itself would diverge
        raise ConfigError(f'{loop.summary()}; lower its gains or raise the sample rate')
    sampled = sampled_loop(plant, laws, dt)
    disc = discrete_frf(plant, laws, dt, line_freq(cfg), f'tcp_force_{d}', sampled)
    if dampers is None:         # laws with dynamics of their own: their continuous loop
        frf = continuous_loop_frf(plant, laws, f'tcp_displacement_{d}', f'tcp_force_{d}')
        cont, dampers = frf(freq), {}
    elif drives is not None:
        raise ConfigError(f'scenario {scenario}: viscous dampers on a plant with the feed '
                          "drives' rotors have no continuous model here")
    else:
        cont = continuous_frf(model.plant, dampers, freq, f'tcp_displacement_{d}',
                              f'tcp_force_{d}')
        frf = plant_pair_frf(model.plant, f'tcp_displacement_{d}', f'tcp_force_{d}', dampers)
    peak = exact_peak(frf, float(cfg.band[0]), float(cfg.f_max), freq)
    return ScenarioAnalytic(scenario, laws, dampers, cont, disc, scenario_pma(scenario), frf,
                            peak, loop, sampled, model.position, plant=plant)


def checked_loop(model: PositionModel, controllers: list[Any], dt: float, policy: str,
                 label: str, drives: DriveSet | None = None) -> LoopCheck:
    """
    :func:`pentapod_sim.sim.stability.check_loop` of a position's sampled loop, kept on disk.

    The check model's eigenvalue problem (about 1,800 states) is most of a scenario's analytic
    work, so its result is kept in :data:`CHECK_CACHE` as ``study_loop_check_<key>.json``,
    keyed by the content of plant and check model, ``dt`` and the controllers; a study run
    again reads it (the radii exactly: JSON keeps every digit) and applies ``policy`` as
    check_loop does. Without a check model nothing is kept (the check is quick). ``drives``:
    the feed drives the scenario's plant steps (plant and check model with their rotors).
    """
    if model.check_plant is None:
        return check_loop(model.plant, None, controllers, dt, policy, label, drives=drives)
    doc = [model.plant.content_hash(), model.check_plant.content_hash(), repr(dt),
           [c.to_json() for c in controllers]] + ([] if drives is None else [repr(drives)])
    key = hashlib.sha256(json.dumps(doc).encode()).hexdigest()[:16]
    path = CHECK_CACHE / f'study_loop_check_{key}.json'
    try:
        kept = LoopCheck(**dict(json.loads(path.read_text()), label=label))
    except (OSError, ValueError, TypeError):
        kept = None                 # none yet, or unreadable: computed (and written) again
    if kept is not None:
        return apply_policy(kept, policy)
    result = check_loop(model.plant, model.check_plant, controllers, dt, policy, label,
                        drives=drives)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        part = path.with_name(f'{path.name}.{os.getpid()}.{threading.get_ident()}.part')
        part.write_text(json.dumps(dataclasses.asdict(result)))
        part.replace(path)          # whole or not at all, for a study running beside
    except OSError as err:
        LOG.warning('truncation check result not kept: %s', err)
    return result


def pma_curves(model: PositionModel, ana: ScenarioAnalytic, cfg: StudyConfig,
               freq: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Analytic stroke [m] and force [N] amplitudes of the scenario's PMA (continuous loop)."""
    assert ana.pma is not None
    d = cfg.direction
    v = continuous_frf(model.plant, ana.dampers, freq, f'pma_mount_velocity_{d}',
                       f'tcp_force_{d}')
    return pma_requirements(v, freq, ana.pma.mass, ana.pma.gain, cfg.pma_force_amplitude)


def pma_designs(model: PositionModel, ana: ScenarioAnalytic,
                cfg: StudyConfig) -> tuple[PmaDesign, PmaDesign]:
    """
    The scenario's PMA as run (ideal) and with the study's high-pass.

    Both in the continuous closed loop with the scenario's other viscous dampers.
    """
    assert ana.pma is not None
    d, mass, gain = cfg.direction, ana.pma.mass, ana.pma.gain
    return (pma_design(model.plant, d, mass, gain, 0.0, ana.dampers),
            pma_design(model.plant, d, mass, gain, cfg.pma_highpass_hz, ana.dampers))


def measure(run: RunResult, cfg: StudyConfig) -> Measured:
    """
    The TCP FRF (and PMA stroke and force FRFs) at the lines of a multisine run's bag.

    Synchronous averaging over the periods after the settling ones
    (:func:`pentapod_sim.analysis.frf.from_run.frfs_from_bag`), and the periodicity check:
    the largest difference between the first and the last of those periods of the TCP
    displacement, relative to its largest value (rounding for a run that started at the
    periodic steady state of a loop the testbed follows exactly; a transient shows there).
    """
    d = cfg.direction
    outputs = [f'{TCP_STATE}.position.tcp_{d}']
    pma = run.scenario.startswith('pma')
    if pma:
        outputs.append(f'{PMA_STATE}.effort.pma_{d}')
    frfs = frfs_from_bag(run.bag, outputs)
    bag = open_bag(run.bag)
    y = bag.series(outputs[0]).values
    n = int(round(cfg.period / cfg.dt))
    s, e = cfg.settle_periods * n, (cfg.settle_periods + cfg.periods) * n
    first, last = y[s:s + n], y[e - n:e]
    periodicity = float(np.abs(last - first).max() / np.abs(y[s:e]).max())
    counts = {t: bag.topic(t).count for t in (TCP_STATE, EXCITATION)}
    result = Measured(run, frfs.freq, frfs.H[0, 0], periodicity, n_messages=counts)
    if pma:
        result.pma_force = frfs.H[1, 0]
        stroke = bag.series(f'{PMA_STATE}.position.pma_{d}').values[:e]
        result.pma_stroke = _stroke_frf(bag.series(f'{EXCITATION}.force.{d}').values[:e],
                                        stroke, cfg, frfs.freq)
    return result


def _stroke_frf(force: FloatArray, stroke: FloatArray, cfg: StudyConfig,
                lines: FloatArray) -> ComplexArray:
    """
    Stroke / force at the lines, the proof mass's drift removed.

    An ideal PMA has no spring: any constant proof-mass velocity is a solution, and its node
    starts the mass at rest, not at the periodic solution's mean velocity. The stroke is then
    periodic plus a ramp; the ramp's slope is the change of the period mean from the first
    analysed period to the last, and is removed before the synchronous average.
    """
    n = int(round(cfg.period / cfg.dt))
    s, e = cfg.settle_periods * n, (cfg.settle_periods + cfg.periods) * n
    slope = 0.0
    if cfg.periods > 1:
        slope = ((stroke[e - n:e].mean() - stroke[s:s + n].mean())
                 / ((cfg.periods - 1) * n))
    flat = stroke - slope * np.arange(stroke.size)
    frf = synchronous_frf(force, flat, cfg.dt, n, cfg.settle_periods, lines)
    return np.asarray(frf.H, dtype=np.complex128)


def deviation_db(measured: Measured, disc: DiscreteFrf, output: str) -> tuple[float, float]:
    """
    Largest |dB| difference between measured and sampled-loop analytic FRF over every line.

    Returns
    -------
    max_db, peak_db : float
        Largest deviation [dB] over all lines, and the measured peak over the analytic one,
        both the largest over the lines [dB].
    """
    if measured.freq.shape != disc.freq.shape or not np.allclose(measured.freq, disc.freq):
        raise ValueError('measured FRF lines differ from the analytic ones (period, band, rate)')
    h_mes, h_ana = np.abs(measured.h), np.abs(disc.outputs[output])
    diff = 20 * np.log10(h_mes / h_ana)
    return float(np.max(np.abs(diff))), float(20 * np.log10(h_mes.max() / h_ana.max()))


def step_series(run: RunResult,
                cfg: StudyConfig) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Time [s], stroke [m] and force [N] of the PMA in a step-response run."""
    bag = open_bag(run.bag)
    d = cfg.direction
    stroke = bag.series(f'{PMA_STATE}.position.pma_{d}')
    force = bag.series(f'{PMA_STATE}.effort.pma_{d}')
    return stroke.time, stroke.values, force.values
