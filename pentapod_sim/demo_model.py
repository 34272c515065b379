"""
Small synthetic plant models with the real port names, for tests, benchmarks and demos.

The model is modal (mass-normalised, so modal mass 1 kg per mode) with random but collocated
input/output vectors: each velocity output row equals the modal input column of its
collocated input (docs/architecture.md), so velocity feedback ``u = -b v`` only dissipates.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from pentapod_sim.plant_model import PlantModel
from pentapod_sim.ports import collocated_output, INPUT_NAMES, OUTPUT_NAMES


def demo_model(n_modes: int = 6, f_min: float = 20.0, f_max: float = 300.0,
               zeta: float = 0.001, inputs: Sequence[str] = INPUT_NAMES,
               input_scale: float = 0.05, seed: int = 0,
               feedthrough: float = 0.0) -> PlantModel:
    """
    Random collocated modal plant.

    Parameters
    ----------
    n_modes : int
        Number of modes (2 n_modes states).
    f_min, f_max : float
        Natural frequencies spread log-evenly over [f_min, f_max] [Hz].
    zeta : float
        Modal damping ratio [-].
    inputs : sequence of str
        Input ports; the outputs are every collocated displacement and velocity output.
    input_scale : float
        RMS of the modal input entries [1/sqrt(kg)] (0.05: ~400 kg effective mass per port).
    seed : int
        Random seed.
    feedthrough : float
        Scale of a random feed-through D on displacement outputs [m/N] (0 = none).
    """
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi * np.geomspace(f_min, f_max, n_modes)
    inputs = list(inputs)
    b = input_scale * rng.standard_normal((n_modes, len(inputs)))
    outputs, c_disp, c_vel, units = [], [], [], []
    for kind in ('displacement', 'velocity'):
        for j, name in enumerate(inputs):
            try:
                out = collocated_output(name, kind)
            except KeyError:   # PortError: the PMA has no displacement output
                continue
            outputs.append(out)
            zero = np.zeros(n_modes)
            c_disp.append(b[:, j] if kind == 'displacement' else zero)
            c_vel.append(b[:, j] if kind == 'velocity' else zero)
            units.append('m/s' if kind == 'velocity' else 'm')
    order = [outputs.index(n) for n in OUTPUT_NAMES if n in outputs]
    outputs = [outputs[i] for i in order]
    c_disp = np.array(c_disp)[order]
    c_vel = np.array(c_vel)[order]
    d = np.zeros((len(outputs), len(inputs)))
    if feedthrough:
        disp_rows = [i for i, n in enumerate(outputs) if 'velocity' not in n
                     and 'rate' not in n]
        d[disp_rows] = feedthrough * rng.standard_normal((len(disp_rows), len(inputs)))
    return PlantModel(omega, np.full(n_modes, zeta), b, c_disp, c_vel, d, inputs, outputs,
                      ['N'] * len(inputs), [units[i] for i in order],
                      list(inputs), list(outputs), {'synthetic': True, 'seed': seed})
