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
    FloatArray,
    Measured,
    PmaSpec,
    PositionModel,
    ScenarioAnalytic,
)
from pentapod_damper.study.runs import RunResult
from pentapod_sim.analysis.bag.reader import open_bag
from pentapod_sim.analysis.frf.estimation import frf_from_series
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
from pentapod_sim.plant.frf_peaks import exact_peak, plant_pair_frf
from pentapod_sim.scenario.files import read_scenario
from pentapod_sim.sim.controllers import controller_of
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


def welch_freq(cfg: StudyConfig) -> FloatArray:
    """Frequency bins [Hz] of the measured FRFs (Welch segments of ``nperseg``), DC left out."""
    freq = np.fft.rfftfreq(cfg.nperseg, cfg.dt)
    return np.asarray(freq[(freq > 0) & (freq <= cfg.f_max)], dtype=np.float64)


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
    on the bins of the measured FRFs (:func:`welch_freq`), so both can be compared bin by bin.
    The sampled loop is checked on the plant and the check model
    (:func:`pentapod_sim.sim.stability.check_loop`, policy ``cfg.check_policy``); a loop
    unstable on the plant itself is refused whatever the policy.
    """
    d = cfg.direction
    dt = cfg.dt
    sections = read_scenario(scenario).sections
    laws = scenario_laws(sections, dt)
    dampers = viscous_equivalent(laws)
    loop = checked_loop(model, [controller_of(law) for law in laws], dt, cfg.check_policy,
                        f'scenario {scenario} at {model.position}')
    if loop.plant_radius >= 1.0:       # whatever the policy: the run itself would diverge
        raise ConfigError(f'{loop.summary()}; lower its gains or raise the sample rate')
    sampled = sampled_loop(model.plant, laws, dt)
    disc = discrete_frf(model.plant, laws, dt, welch_freq(cfg), f'tcp_force_{d}', sampled)
    if dampers is None:         # laws with dynamics of their own: their continuous loop
        frf = continuous_loop_frf(model.plant, laws, f'tcp_displacement_{d}', f'tcp_force_{d}')
        cont, dampers = frf(freq), {}
    else:
        cont = continuous_frf(model.plant, dampers, freq, f'tcp_displacement_{d}',
                              f'tcp_force_{d}')
        frf = plant_pair_frf(model.plant, f'tcp_displacement_{d}', f'tcp_force_{d}', dampers)
    peak = exact_peak(frf, float(cfg.band[0]), float(cfg.f_max), freq)
    return ScenarioAnalytic(scenario, laws, dampers, cont, disc, scenario_pma(scenario), frf,
                            peak, loop, sampled, model.position)


def checked_loop(model: PositionModel, controllers: list[Any], dt: float, policy: str,
                 label: str) -> LoopCheck:
    """
    :func:`pentapod_sim.sim.stability.check_loop` of a position's sampled loop, kept on disk.

    The check model's eigenvalue problem (about 1,800 states) is most of a scenario's analytic
    work, so its result is kept in :data:`CHECK_CACHE` as ``study_loop_check_<key>.json``,
    keyed by the content of plant and check model, ``dt`` and the controllers; a study run
    again reads it (the radii exactly: JSON keeps every digit) and applies ``policy`` as
    check_loop does. Without a check model nothing is kept (the check is quick).
    """
    if model.check_plant is None:
        return check_loop(model.plant, None, controllers, dt, policy, label)
    doc = [model.plant.content_hash(), model.check_plant.content_hash(), repr(dt),
           [c.to_json() for c in controllers]]
    key = hashlib.sha256(json.dumps(doc).encode()).hexdigest()[:16]
    path = CHECK_CACHE / f'study_loop_check_{key}.json'
    try:
        kept = LoopCheck(**dict(json.loads(path.read_text()), label=label))
    except (OSError, ValueError, TypeError):
        kept = None                 # none yet, or unreadable: computed (and written) again
    if kept is not None:
        return apply_policy(kept, policy)
    result = check_loop(model.plant, model.check_plant, controllers, dt, policy, label)
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
    """Estimate the TCP FRF (H1, Welch/Hann) and PMA stroke/force FRFs from a run's bag."""
    d = cfg.direction
    bag = open_bag(run.bag)
    force = bag.series(f'{EXCITATION}.force.{d}')
    tcp = frf_from_series(force, bag.series(f'{TCP_STATE}.position.tcp_{d}'),
                          'random', cfg.nperseg)
    counts = {t: bag.topic(t).count for t in (TCP_STATE, EXCITATION)}
    result = Measured(run, tcp.freq, tcp.H, tcp.coherence, n_messages=counts)
    if run.scenario.startswith('pma'):
        stroke = frf_from_series(force, bag.series(f'{PMA_STATE}.position.pma_{d}'),
                                 'random', cfg.nperseg)
        effort = frf_from_series(force, bag.series(f'{PMA_STATE}.effort.pma_{d}'),
                                 'random', cfg.nperseg)
        result.pma_stroke, result.pma_force = stroke.H, effort.H
    return result


def deviation_db(measured: Measured, disc: DiscreteFrf, output: str, cfg: StudyConfig,
                 f_lo: float) -> tuple[float, float]:
    """
    Largest |dB| difference between measured and sampled-loop analytic FRF.

    Only bins in [f_lo, f_max] with coherence >= coherence_min count.

    Returns
    -------
    max_db, share : float
        Largest deviation [dB] and the share of the band's bins that were compared.
    """
    idx = np.searchsorted(measured.freq, disc.freq)
    if np.any(idx >= measured.freq.size) or not np.allclose(measured.freq[idx], disc.freq):
        raise ValueError('measured FRF bins differ from the analytic ones (nperseg, rate)')
    h_mes, coh = measured.h[idx], measured.coherence[idx]
    band = disc.freq >= f_lo
    good = band & (coh >= cfg.coherence_min)
    if not np.any(good):
        return float('nan'), 0.0
    diff = 20 * np.log10(np.abs(h_mes[good]) / np.abs(disc.outputs[output][good]))
    return float(np.max(np.abs(diff))), float(good.sum() / band.sum())


def step_series(run: RunResult,
                cfg: StudyConfig) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Time [s], stroke [m] and force [N] of the PMA in a step-response run."""
    bag = open_bag(run.bag)
    d = cfg.direction
    stroke = bag.series(f'{PMA_STATE}.position.pma_{d}')
    force = bag.series(f'{PMA_STATE}.effort.pma_{d}')
    return stroke.time, stroke.values, force.values
