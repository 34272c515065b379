"""
What a proof-mass actuator must deliver: stroke and force against frequency.

Worst cases in a stated band and values at stated frequencies, for the ideal law and its
high-pass variant. The ideal law (:class:`pentapod_damper.laws.ProofMassActuator` without
filter) accelerates the proof mass m_a by ``g v`` (v: mount velocity), so it acts as a
viscous damper ``b = m_a g``, but its stroke grows without bound towards low frequencies
(``|x| g / w`` for a quasi-static mount motion x). The high-pass variant filters v with a
2nd-order Butterworth high-pass first (analog here; the law's digital filter matches it far
below Nyquist): below the corner the proof mass stops following, the stroke tends to the
mount's own motion and stays bounded, at the price of less damping near the corner. The
continuous closed loop (plant plus PMA law) is held in pole-residue form
(:mod:`pentapod_sim.plant.frf_peaks`), so worst cases are searched at the resonances and band
edges, not read from a grid.

Units: frequencies [Hz], mass [kg], gain [1/s], force amplitude [N], stroke [m].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import control
import numpy as np
import numpy.typing as npt
import scipy.signal

from pentapod_damper.study.analytic import pma_requirements
from pentapod_sim.plant.frf_peaks import (
    exact_peak,
    maximise_near_poles,
    Peak,
    PoleResidueFrf,
)
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.ports import collocated_output


def highpass_response(freq_hz: npt.ArrayLike, highpass_hz: float) -> np.ndarray:
    """Analog 2nd-order Butterworth high-pass at ``freq_hz`` (1 where ``highpass_hz`` is 0)."""
    freq = np.asarray(freq_hz, dtype=float)
    if highpass_hz <= 0:
        return np.ones(freq.shape, dtype=complex)
    num, den = scipy.signal.butter(2, 2 * np.pi * highpass_hz, 'highpass', analog=True)
    return scipy.signal.freqs(num, den, 2 * np.pi * freq)[1]


def _gain_block(plant: PlantModel,
                entries: Mapping[tuple[str, str], control.StateSpace]) -> control.StateSpace:
    """Controller ``u = K(s) y`` over all plant ports from SISO blocks (input, output) -> K."""
    n_in, n_out = len(plant.input_names), len(plant.output_names)
    total = control.ss([], [], [], np.zeros((n_in, n_out)))
    for (inp, out), block in entries.items():
        pick = np.zeros((1, n_out))
        pick[0, plant.output_names.index(out)] = 1.0
        place = np.zeros((n_in, 1))
        place[plant.input_names.index(inp), 0] = 1.0
        total = control.parallel(total, control.ss([], [], [], place) * block
                                 * control.ss([], [], [], pick))
    return total


@dataclass(frozen=True)
class PmaDesign:
    """
    One PMA law in the continuous closed loop, excited by a TCP force.

    Attributes
    ----------
    mass, gain, highpass_hz : float
        Proof mass [kg], gain g [1/s], high-pass corner [Hz] (0: ideal law).
    velocity : PoleResidueFrf
        Mount velocity / TCP force [m/(s N)].
    tcp : PoleResidueFrf
        TCP displacement / TCP force [m/N] in the PMA's direction.
    """

    mass: float
    gain: float
    highpass_hz: float
    velocity: PoleResidueFrf
    tcp: PoleResidueFrf

    def stroke_force(self, freq_hz: npt.ArrayLike,
                     amplitude: float) -> tuple[np.ndarray, np.ndarray]:
        """Stroke [m] and force [N] amplitudes for a harmonic TCP force of ``amplitude`` N."""
        freq = np.asarray(freq_hz, dtype=float)
        return pma_requirements(self.velocity(freq), freq, self.mass, self.gain, amplitude,
                                highpass_response(freq, self.highpass_hz))

    def worst(self, what: str, f_lo: float, f_hi: float, amplitude: float,
              grid_hz: npt.ArrayLike | None = None) -> Peak:
        """Largest stroke [m] or force [N] (``what``) on [f_lo, f_hi] Hz."""
        pick = 0 if what == 'stroke' else 1
        return maximise_near_poles(lambda f: self.stroke_force(f, amplitude)[pick],
                                   self.velocity.poles, f_lo, f_hi, grid_hz)

    def tcp_peak(self, f_lo: float, f_hi: float) -> Peak:
        """Exact TCP compliance peak [m/N] with this PMA on [f_lo, f_hi] Hz."""
        return exact_peak(self.tcp, f_lo, f_hi)


def pma_design(plant: PlantModel, direction: str, mass: float, gain: float,
               highpass_hz: float = 0.0, dampers: Mapping[str, float] | None = None
               ) -> PmaDesign:
    """
    Close the continuous loop of a PMA in ``direction`` (x, y, z) on a modal plant.

    The law drives ``pma_force_<d>`` with ``-m_a g H(s) v`` (H: high-pass or 1) from
    ``pma_mount_velocity_<d>``; the TCP force in ``d`` excites. ``dampers`` (input port ->
    viscous gain) adds other viscous dampers of the scenario.
    """
    port = f'pma_force_{direction}'
    law = control.ss([], [], [], [[mass * gain]])
    if highpass_hz > 0:
        num, den = scipy.signal.butter(2, 2 * np.pi * highpass_hz, 'highpass', analog=True)
        law = law * control.ss(control.tf(num, den))
    blocks = {(inp, collocated_output(inp, 'velocity')): control.ss([], [], [], [[g]])
              for inp, g in (dampers or {}).items() if inp != port}
    blocks[(port, collocated_output(port, 'velocity'))] = law
    feedback = _gain_block(plant, blocks)
    closed = control.feedback(plant.to_statespace(), feedback, sign=-1)
    i = plant.input_names.index(f'tcp_force_{direction}')

    def pair(output: str) -> PoleResidueFrf:
        o = plant.output_names.index(output)
        return PoleResidueFrf.from_state_space(closed.A, closed.B[:, i], closed.C[o],
                                               float(closed.D[o, i]))

    return PmaDesign(float(mass), float(gain), float(highpass_hz),
                     pair(f'pma_mount_velocity_{direction}'),
                     pair(f'tcp_displacement_{direction}'))


def requirement_row(design: PmaDesign, amplitude: float,
                    excitation_band: tuple[float, float], stated_band: Sequence[float],
                    frequencies: Sequence[float], grid_hz: npt.NDArray[np.float64]
                    ) -> dict[str, float]:
    """
    Table row of one PMA design: worst cases in both bands, values at stated frequencies.

    Columns: ``max_stroke_mm`` / ``at_hz`` and ``max_force_N`` / ``force_at_hz`` over the
    excitation band; ``band_*`` over the stated band; ``stroke_mm_at_<f>_hz``,
    ``force_N_at_<f>_hz`` and ``free_mass_stroke_mm_at_<f>_hz`` (``F / (m_a w^2)``: the stroke
    if the proof mass took the whole force) per stated frequency; the exact TCP peak.
    """
    row: dict[str, float] = {}
    for prefix, (lo, hi) in (('', excitation_band), ('band_', stated_band)):
        worst_stroke = design.worst('stroke', float(lo), float(hi), amplitude, grid_hz)
        worst_force = design.worst('force', float(lo), float(hi), amplitude, grid_hz)
        row.update({f'{prefix}max_stroke_mm': worst_stroke.value * 1e3,
                    f'{prefix}{"stroke_" if prefix else ""}at_hz': worst_stroke.freq_hz,
                    f'{prefix}max_force_N': worst_force.value,
                    f'{prefix}force_at_hz': worst_force.freq_hz})
    freq = np.asarray(frequencies, dtype=float)
    stroke, force = design.stroke_force(freq, amplitude)
    for f, s, fa in zip(freq, stroke, force):
        row[f'stroke_mm_at_{f:g}_hz'] = float(s * 1e3)
        row[f'force_N_at_{f:g}_hz'] = float(fa)
        row[f'free_mass_stroke_mm_at_{f:g}_hz'] = float(
            amplitude / (design.mass * (2 * np.pi * f) ** 2) * 1e3)
    peak = design.tcp_peak(float(excitation_band[0]), float(excitation_band[1]))
    row.update(tcp_peak_um_per_N=peak.value * 1e6, tcp_peak_hz=peak.freq_hz)
    return row


def bounded_stroke(design: PmaDesign, amplitude: float, f_hi: float) -> Peak:
    """
    Largest stroke [m] over all frequencies up to ``f_hi`` (the high-pass variant only).

    Searched from 1 mHz on a log grid and at the poles; the ideal law has no such bound.
    """
    if design.highpass_hz <= 0:
        raise ValueError('the stroke of the ideal PMA grows without bound below its band')
    grid = np.geomspace(1e-3, f_hi, 3000)
    return design.worst('stroke', 1e-3, f_hi, amplitude, grid)
