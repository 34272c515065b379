"""
Closed loops of one pose: TCP compliance, dominant-mode damping, struts-1+2 share, PMA needs.

Everything is the continuous loop with ideal viscous dampers (the paper's view), computed with
the study's functions (:mod:`pentapod_damper.study.analytic`) on the plant restricted to the
ports the loop and the results need. The closed-loop poles are the eigenvalues of the
closed-loop A (:func:`pentapod_sim.plant.frf.damper_feedback`); each is paired with an open-loop
mode by the modal assurance criterion in modal coordinates (mass-normalised modes, so it is
the mass-weighted MAC of the FE shapes). The sampled lockstep loop's spectral radius
(:func:`pentapod_sim.sim.stability.plant_radius`) says whether the testbed could run it.

A scenario whose plant steps the feed drives (its ``drives``) is closed on the plant with the
drives' rotors (:class:`pentapod_sim.plant.drives.DrivenPlant`) and its drives' cascade (the
machine: not scaled by a gain factor); its continuous loop is then the cascade's continuous
model with the viscous dampers (:func:`pentapod_sim.sim.loop_poles.continuous_loop_system`),
its poles paired with the open-loop modes by the modal part of their eigenvectors. The open
loop stays the locked machine (the FE model's drive links).

Units: compliance m/N, frequencies Hz, damping ratios -, stroke m, force N.
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import control
import numpy as np
import numpy.typing as npt
import scipy.linalg as sla

from pentapod_damper.laws import ProofMassActuator
from pentapod_damper.laws.linear import DrivesLaw
from pentapod_damper.scenario_laws import continuous_dampers, scenario_laws
from pentapod_damper.study.analytic import (
    continuous_frf,
    improvement_share,
    peak_and_rms,
    pma_requirements,
)
from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.drives import DriveSet, with_drives
from pentapod_sim.plant.frf import damper_feedback
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.sim.controllers import controller_blocks, controller_of, DiscreteController
from pentapod_sim.sim.loop_poles import continuous_loop_system
from pentapod_sim.sim.stability import plant_radius

#: TCP directions; the compliance of direction d is displacement d / force d.
DIRECTIONS = ('x', 'y', 'z')
#: Largest eigenvector condition number of the eigen-decomposition FRF.
COND_MAX = 1e10


class Loop:
    """
    One damped loop: a scenario's laws with their gains scaled by ``factor``.

    Attributes
    ----------
    dampers : dict
        Input port -> viscous gain [N s/m or N m s/rad] (an ideal PMA is ``m_a g``).
    pmas : list of ProofMassActuator
        The scenario's PMAs (their gain g scaled by ``factor``).
    controllers : list of DiscreteController
        Linear models of the laws for the sampled-loop check (the drives' cascade too).
    drives : DriveSet or None
        The feed drives the scenario's plant steps (its ``drives``).
    cascade : list of FeedDrives
        The scenario's drives' cascades (their continuous models close the continuous loop).
    """

    def __init__(self, sections: dict[str, dict[str, Any]], dt: float,
                 factor: float = 1.0, drives: DriveSet | None = None) -> None:
        every = scenario_laws(sections, dt)
        self.drives = drives
        self.cascade = [law.law for law in every if isinstance(law, DrivesLaw)]
        if self.cascade and drives is None:
            raise ConfigError("a damper node runs the feed drives' cascade (drive_struts) but "
                              "the scenario's plant has no drives (its parameter drives)")
        laws = [law for law in every if not isinstance(law, DrivesLaw)]
        self.factor = float(factor)
        self.dampers = {p: g * factor for p, g in continuous_dampers(laws).items()}
        self.pmas = [law for law in laws if isinstance(law, ProofMassActuator)]
        self.controllers = [cascade.discrete(dt) for cascade in self.cascade]
        for law in laws:        # u = factor * (c xc + d y): the law's effort scaled
            ctrl = controller_of(law)
            self.controllers.append(DiscreteController(
                ctrl.sensor_ports, ctrl.actuator_ports, ctrl.a, ctrl.b, ctrl.c * factor,
                ctrl.d * factor))

    def drive_ports(self) -> tuple[list[str], list[str]]:
        """The plant ports the drives' rotors need (inputs, outputs); none without drives."""
        if self.drives is None:
            return [], []
        struts = self.drives.struts
        return ([f'strut{i}_drive_force' for i in struts],
                [f'strut{i}_{kind}' for i in struts for kind in ('drive_displacement', 'force')])

    def continuous_system(self, sub: PlantModel) -> Any:
        """
        The continuous loop on ``sub`` with the drives' rotors: cascade and dampers.

        A state space (``A``, ``B``, ``C``, ``D`` on the driven plant's ports, the plant's
        first) of the state ``[x (plant), rotors, cascade]`` scaled by ``T`` (``scale``, the
        diagonal of :func:`scipy.linalg.matrix_balance`: ``A = T^-1 A_loop T``): the rotors'
        forces [N] and the modal coordinates differ by orders of magnitude, which leaves the
        unbalanced eigenvectors too ill-conditioned for the eigen-decomposition FRF. The
        original eigenvectors are ``T v``.
        """
        driven = with_drives(sub, self.drives)
        static = [DiscreteController.static(
            [collocated_output(p, 'velocity')], [p], np.array([[-g]]))
            for p, g in self.dampers.items()]
        ctrls = [cascade.continuous() for cascade in self.cascade] + static
        a, b, c_y = continuous_loop_system(driven, ctrls)
        d = driven.state_matrices()[3]
        gain = controller_blocks(ctrls, driven.input_names, driven.output_names)[0]
        direct = d @ np.linalg.inv(np.eye(len(driven.input_names)) - gain @ d)
        balanced, (scale, _) = sla.matrix_balance(a, permute=False, separate=True)
        return SimpleNamespace(A=balanced, B=b / scale[:, None], C=c_y * scale[None, :],
                               D=direct, scale=scale)


def ports_needed(loops: list[Loop]) -> tuple[list[str], list[str]]:
    """Inputs and outputs of the TCP pairs, every damper and every PMA mount."""
    inputs = [f'tcp_force_{d}' for d in DIRECTIONS]
    outputs = [f'tcp_displacement_{d}' for d in DIRECTIONS]
    for loop in loops:
        for port in loop.dampers:
            inputs.append(port)
            outputs.append(collocated_output(port, 'velocity'))
        motors = {p for cascade in loop.cascade
                  for p in cascade.sensor_ports + cascade.actuator_ports if 'motor' in p}
        for ctrl in loop.controllers:
            inputs += [p for p in ctrl.actuator_ports if p not in motors]
            outputs += [p for p in ctrl.sensor_ports if p not in motors]
        drive_in, drive_out = loop.drive_ports()
        inputs += drive_in
        outputs += drive_out
    return list(dict.fromkeys(inputs)), list(dict.fromkeys(outputs))


def dominant_modes(plant: PlantModel) -> dict[str, int]:
    """
    Index of the mode with the largest resonance peak of each TCP compliance.

    The peak of mode j in |H_dd| is ``|c_dj b_jd| / (2 zeta_j omega_j^2)``.
    """
    out = {}
    for d in DIRECTIONS:
        o = plant.output_names.index(f'tcp_displacement_{d}')
        i = plant.input_names.index(f'tcp_force_{d}')
        peak = np.abs(plant.c_disp[o] * plant.b[:, i]) / (2 * plant.zeta * plant.omega ** 2)
        out[d] = int(np.argmax(peak))
    return out


def paired_damping(lam: np.ndarray, vec: np.ndarray,
                   modes: dict[str, int]) -> dict[str, tuple[float, float]]:
    """
    Damping ratio and frequency [Hz] of the closed-loop pole of each open-loop mode.

    Parameters
    ----------
    lam, vec : ndarray
        Eigenvalues and eigenvectors of the closed-loop A, states ``[q; dq]`` (modal
        coordinates and their rates).
    modes : dict
        Name -> open-loop mode index j.

    Returns
    -------
    dict
        Name -> (zeta, f); the pole whose eigenvector's modal part has the largest share
        ``|q_j|^2 / |q|^2`` (the MAC with mode j) among poles with Im >= 0.
    """
    m = vec.shape[0] // 2
    upper = lam.imag >= 0
    q = np.abs(vec[:m, upper]) ** 2
    mac = q / np.maximum(q.sum(axis=0, keepdims=True), np.finfo(float).tiny)
    out = {}
    for name, j in modes.items():
        pole = lam[upper][int(np.argmax(mac[j]))]
        out[name] = (float(-pole.real / abs(pole)), float(abs(pole) / (2 * np.pi)))
    return out


def pair_frfs(sys: control.StateSpace, lam: np.ndarray, vec: np.ndarray,
              pairs: list[tuple[str, str]], freq: np.ndarray, plant: PlantModel,
              dampers: dict[str, float], fallback: bool = True
              ) -> list[npt.NDArray[np.complex128]]:
    """
    FRFs ``output / input`` of a state space from its eigen-decomposition, pair by pair.

    Only the pairs asked for are evaluated (``C v (jw - lambda)^-1 v^-1 B + D``, O(n F) each);
    a (nearly) defective closed loop falls back to the study's
    :func:`pentapod_damper.study.analytic.continuous_frf` (with ``fallback``; else ConfigError:
    a loop with the drives has no such fallback).
    """
    if np.linalg.cond(vec) > COND_MAX:
        if not fallback:
            raise ConfigError('the continuous loop with the drives is (nearly) defective: no '
                              'FRF from its eigenvectors')
        return [continuous_frf(plant, dampers, freq, o, i) for o, i in pairs]
    rows = [plant.output_names.index(o) for o, _ in pairs]
    cols = [plant.input_names.index(i) for _, i in pairs]
    left = sys.C[rows] @ vec
    right = np.linalg.solve(vec, sys.B[:, cols]).T
    resolvent = 1.0 / (2j * np.pi * freq[None, :] - lam[:, None])
    h = (left * right) @ resolvent + sys.D[rows, cols][:, None]
    return list(h)


def loop_columns(plant: PlantModel, loops: dict[str, Loop], freq: np.ndarray,
                 band: tuple[float, float], dt: float, pma_force: float,
                 shares: list[tuple[str, str, str]]) -> dict[str, Any]:
    """
    Result columns of the open loop and of every damped loop at one pose.

    Parameters
    ----------
    plant : PlantModel
        Reduced plant of the pose.
    loops : dict
        Column label -> :class:`Loop`.
    freq : (F,) ndarray
        Uniform frequency grid [Hz].
    band : (lo, hi)
        Band [Hz] of peak and RMS.
    dt : float
        Sample time [s] of the sampled-loop check.
    pma_force : float
        Harmonic TCP force amplitude [N] of the PMA stroke and force.
    shares : list
        (suffix, label of struts 1+2, label of all struts) of the share columns.
    """
    lo, hi = band
    in_band = (freq >= lo) & (freq <= hi)
    inputs, outputs = ports_needed(list(loops.values()))
    sub = plant.select(inputs, outputs)
    dom = dominant_modes(sub)
    row: dict[str, Any] = {}
    for label, loop in [('open', None)] + list(loops.items()):
        dampers = loop.dampers if loop else {}
        driven = loop is not None and loop.drives is not None
        if loop is not None and loop.drives is not None:     # (driven; narrows for mypy)
            sys = loop.continuous_system(sub)
        else:
            sys = damper_feedback(sub, dampers) if dampers else sub.to_statespace()
        lam, vec = sla.eig(sys.A)
        modal = vec[:2 * sub.n_modes]               # the modal part, in modal coordinates
        if driven:
            modal = modal * sys.scale[:2 * sub.n_modes, None]
        damping = paired_damping(lam, modal, dom)
        pmas = [(pma, port) for pma in (loop.pmas if loop else []) for port in pma.sensor_ports]
        pairs = [(f'tcp_displacement_{d}', f'tcp_force_{d}') for d in DIRECTIONS]
        pairs += [(port, f'tcp_force_{port[-1]}') for _, port in pmas]
        frfs = pair_frfs(sys, lam, vec, pairs, freq, sub, dampers, fallback=not driven)
        for d, h in zip(DIRECTIONS, frfs):
            row[f'peak_{d}{d}_{label}'], row[f'rms_{d}{d}_{label}'] = peak_and_rms(h, freq, lo, hi)
            row[f'zeta_{d}{d}_{label}'] = damping[d][0]
            if loop is None:
                row[f'f_peak_{d}{d}_open'] = float(freq[in_band][np.argmax(np.abs(h[in_band]))])
                row[f'dom_f_{d}{d}'] = float(sub.frequencies_hz[dom[d]])
        if loop is None:
            continue
        row[f'rho_{label}'] = plant_radius(with_drives(sub, loop.drives), loop.controllers,
                                           dt)[0]
        for (pma, port), v in zip(pmas, frfs[len(DIRECTIONS):]):
            stroke, force = pma_requirements(v, freq, pma.mass, pma.gain * loop.factor,
                                             pma_force)
            row[f'pma_stroke_{port[-1]}_{label}'] = float(stroke[in_band].max())
            row[f'pma_force_{port[-1]}_{label}'] = float(force[in_band].max())
    for tail, partial, full in shares:
        for d in DIRECTIONS:
            for kind in ('peak', 'rms'):
                row[f'share_{kind}_{d}{d}{tail}'] = improvement_share(
                    row[f'{kind}_{d}{d}_open'], row[f'{kind}_{d}{d}_{partial}'],
                    row[f'{kind}_{d}{d}_{full}'])
    return row
