"""
The models a damper design is judged on at one machine position.

* the **design plant**: every FE mode below ``modes_f_max`` that the relevance rules of
  config/reduction.yaml keep, plus those the feed drives' collocated ports need (the strut
  on its drive link, 710-750 Hz), with the static correction;
* the **check model**: every FE mode below ``max(5 kHz, 2 x sample rate)``
  (:mod:`pentapod_sim.plant.check_model`), on which the sampled loop must be stable too;
* **stiffness corners**: the design plant of the machine with the strut, joint (BP and WP)
  and foot stiffnesses scaled by the factors of :data:`CORNERS` (FE stiffness groups
  ``struts``, ``bp_joints`` + ``wp_joints``, ``installation``), so that a law that only works
  for the nominal machine (a negative stiffness near buckling) is not chosen;
* the strut reference stiffnesses (:class:`~pentapod_sim.sim.law_families.StrutStiffness`),
  the drives' parameters, and the modal strain-energy shares of the modes that dominate the
  TCP (what a strut law can reach).

Units: SI; frequencies in Hz.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
import logging
from pathlib import Path
from typing import Callable

import numpy as np
import scipy.sparse as sp

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.beam import rhs_section
from pentapod_sim.fe.geometry import layout_from_params, solve_pose
from pentapod_sim.fe.machine_data import load_machine, MachineParams
from pentapod_sim.fe.model import FEModel
from pentapod_sim.modes.causes import strain_energy_shares
from pentapod_sim.modes.frame_reduction import build_model
from pentapod_sim.modes.solver import solve_modes
from pentapod_sim.plant.build import keep_by_relevance, plant_from_fe, reduce_plant
from pentapod_sim.plant.check_model import check_f_max, load_or_build_check_model
from pentapod_sim.plant.config import load_reduction_config, ReductionConfig, relevance_rule
from pentapod_sim.plant.drives import DrivenPlant, DriveParams, load_drives
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.sim.law_families import StrutStiffness

LOG = logging.getLogger(__name__)

#: Stiffness corners: name -> (struts, joints, feet) factors.
CORNERS = {'all soft': (0.8, 0.8, 0.8), 'all stiff': (1.2, 1.2, 1.2),
           'soft struts, stiff joints and feet': (0.8, 1.2, 1.2),
           'stiff struts, soft joints and feet': (1.2, 0.8, 0.8)}
#: Stiffness groups of each corner factor.
CORNER_GROUPS = (('struts',), ('bp_joints', 'wp_joints'), ('installation',))
#: Relevance of the feed drives' collocated pairs (added to the config's rules).
DRIVE_RULE = {'inputs': [f'strut{i}_drive_force' for i in range(1, 6)],
              'outputs': [f'strut{i}_drive_displacement' for i in range(1, 6)],
              'rel_limit': 0.01}


@dataclass
class DesignModel:
    """The models of one position (see the module docstring)."""

    position: str
    plant: PlantModel
    check: PlantModel | None
    corners: dict[str, PlantModel]
    drives: DriveParams
    stiffness: StrutStiffness
    energy: dict[str, np.ndarray] = field(default_factory=dict)
    energy_freq_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: The full check model when ``check`` keeps only its modes below a frequency
    #: (:func:`load_design_model`'s ``check_subset_hz``), for the final verification.
    full_check: PlantModel | None = None
    #: The models with the drives' rotors, built once per model (key: '', corner, 'check'):
    #: the check model's exact discretisation is an eigenvalue problem of thousands of states.
    driven: dict[str, DrivenPlant] = field(default_factory=dict, repr=False)

    def with_drives(self, key: str) -> DrivenPlant:
        """The design plant (''), a corner or the check model ('check') with the drives."""
        if key not in self.driven:
            modal = (self.check if key == 'check' else self.corners[key] if key
                     else self.plant)
            if modal is None:
                raise ConfigError(f'{self.position}: no check model was built')
            self.driven[key] = DrivenPlant(modal, self.drives)
        return self.driven[key]


def design_plant(fe: FEModel, cfg: ReductionConfig) -> PlantModel:
    """The relevant modes of ``fe`` (config rules and :data:`DRIVE_RULE`), statically corrected."""
    plant_all, keep = plant_from_fe(fe, cfg, lambda msg: LOG.debug('%s', msg))
    rules = list(cfg.relevance) + [relevance_rule(DRIVE_RULE)]
    keep = keep_by_relevance(plant_all, rules)
    return reduce_plant(plant_all, keep, True)


def scaled(fe: FEModel, factors: tuple[float, float, float]) -> FEModel:
    """``fe`` with the stiffness groups of :data:`CORNER_GROUPS` scaled by ``factors``."""
    groups = dict(fe.stiffness_groups)
    for factor, names in zip(factors, CORNER_GROUPS):
        for name in names:
            if name in groups:
                groups[name] = (factor * groups[name]).tocsr()
    k = sp.csr_matrix(sum(groups.values()))
    return replace(fe, K=k, stiffness_groups=groups)


def strut_stiffness(machine: MachineParams, fe: FEModel, plant: PlantModel,
                    chord_position: float) -> StrutStiffness:
    """Reference stiffnesses of the strut ports at the pose of ``fe`` (:class:`StrutStiffness`)."""
    state = solve_pose(layout_from_params(machine), fe.pose)
    s = machine.struts.section
    sec = rhs_section(s.width, s.height, s.thickness)
    e = machine.materials.steel.youngs_modulus
    length = np.asarray(state.lengths, dtype=float)
    inertia = np.array([sec.iy, sec.iz])
    bending = e * inertia[None, :] / length[:, None]
    a, b = chord_position * length, (1 - chord_position) * length
    chord = 3 * e * inertia[None, :] * length[:, None] / ((a * b) ** 2)[:, None]
    return StrutStiffness(bending, chord, collocated_statics(plant))


def collocated_statics(plant: PlantModel) -> dict[str, float]:
    """Static compliance of every displacement output per unit of its collocated input."""
    a, b, c, d = plant.state_matrices()
    x = np.linalg.solve(a, b) if plant.n_modes else np.zeros((0, b.shape[1]))
    out = {}
    for j, name in enumerate(plant.input_names):
        try:
            sensor = collocated_output(name, 'displacement')
        except KeyError:
            continue
        if sensor in plant.output_names:
            o = plant.output_names.index(sensor)
            out[sensor] = float(d[o, j] - c[o] @ x[:, j])
    return out


def load_design_model(position: str, sample_rate: float = 5000.0,
                      check: bool = True, corners: bool = True,
                      cache_dir: str | Path = 'out/models',
                      reduction_cfg: ReductionConfig | None = None,
                      progress: Callable[[str], None] | None = None,
                      check_subset_hz: float | None = None) -> DesignModel:
    """
    Build the :class:`DesignModel` of a position of config/positions.yaml.

    The check model (every FE mode below ``max(5 kHz, 2 x sample_rate)``) is cached like the
    plant node's (with the package's config files); the design plant and the corners take
    about a second each. ``check_subset_hz``: the check model the tuner uses keeps only the
    check model's modes below this frequency, with the static correction of the others (its
    eigenvalue problems cost about the cube of its states: the 1423 modes below 10 kHz at P1
    cost about 30 s each); the full one stays as ``full_check`` for the final verification.
    """
    say = progress or (lambda msg: LOG.info('%s', msg))
    machine = load_machine()
    cfg = load_reduction_config() if reduction_cfg is None else reduction_cfg
    fe = build_model(machine, position)
    say(f'{position}: design plant')
    plant = design_plant(fe, cfg)
    plant.meta['position'] = position
    check_model = None
    if check:
        f_max = check_f_max(sample_rate)
        say(f'{position}: check model (every mode below {f_max:g} Hz)')
        check_model, origin = load_or_build_check_model(position, f_max, cache_dir)
        LOG.info('%s', origin)
    full_check = check_model
    if check_model is not None and check_subset_hz:
        keep = np.flatnonzero(check_model.omega < 2 * np.pi * check_subset_hz)
        say(f'{position}: the tuner checks on the {keep.size} of {check_model.n_modes} '
            f'check modes below {check_subset_hz:g} Hz (static correction of the others)')
        check_model = reduce_plant(check_model, keep, True)
        check_model.meta['check_f_max_hz'] = float(check_subset_hz)
    corner_plants = {}
    if corners:
        for name, factors in CORNERS.items():
            say(f'{position}: stiffness corner {name}')
            corner_plants[name] = design_plant(scaled(fe, factors), cfg)
    model = DesignModel(position, plant, check_model, corner_plants, load_drives(),
                        strut_stiffness(machine, fe, plant, cfg.chord_position),
                        full_check=full_check)
    modes = solve_modes(fe.K, fe.M, f_max=cfg.modes_f_max)
    shares = strain_energy_shares(fe.stiffness_groups, modes)
    model.energy = {g: shares[:, k] for k, g in enumerate(fe.stiffness_groups)}
    model.energy_freq_hz = np.asarray(modes.frequencies)
    return model
