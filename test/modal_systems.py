"""
Test systems with known poles for the FRF estimators and the modal identification.

* :func:`two_dof`: a 2-DOF mass-spring-damper chain, M, K and a damping matrix built for two
  chosen modal damping ratios; its poles come from the eigenvalues of the state matrix, its FRFs
  from ``(K - w^2 M + j w C)^-1`` (neither uses the modal formula the identification fits).
* :func:`ten_modes`: a modal model of 10 modes with 3 outputs, 0.1 % to 2 % damping.
* :func:`multisine`: a periodic multisine with Schroeder phases on chosen lines.
* :func:`periodic_response`: the exact periodic steady-state output of a continuous system to a
  periodic input (per line ``Y = H(j w) U``), with white noise added in the time domain.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg


class TwoDof:
    """Two masses [kg], springs [N/m], damping for modal ratios; force on mass 1."""

    def __init__(self, zeta=(0.001, 0.02)):
        self.m = np.diag([2.0, 1.0])
        self.k = np.array([[9.0e4 + 5.0e4, -5.0e4], [-5.0e4, 5.0e4]])
        w2, phi = scipy.linalg.eigh(self.k, self.m)  # mass-normalised modes
        wn = np.sqrt(w2)
        self.c = self.m @ phi @ np.diag(2 * np.asarray(zeta) * wn) @ phi.T @ self.m
        a = np.block([[np.zeros((2, 2)), np.eye(2)],
                      [-np.linalg.solve(self.m, self.k), -np.linalg.solve(self.m, self.c)]])
        self.a = a
        self.b = np.vstack([np.zeros((2, 1)), np.linalg.solve(self.m, [[1.0], [0.0]])])
        self.c_out = np.hstack([np.eye(2), np.zeros((2, 2))])  # displacements [m]
        eig = np.linalg.eigvals(a)
        eig = eig[eig.imag > 0]
        eig = eig[np.argsort(np.abs(eig))]
        self.poles = eig
        self.freq_hz = np.abs(eig) / (2 * np.pi)
        self.damping = -eig.real / np.abs(eig)
        # modal constants phi_o phi_1 of mass-normalised modes (normal modes)
        self.modal_constants = phi * phi[0][None, :]

    def frf(self, freq):
        """(2, 1, F) receptance [m/N] of both masses to the force on mass 1."""
        out = np.empty((2, 1, len(freq)), dtype=complex)
        for j, f in enumerate(freq):
            w = 2 * np.pi * f
            out[:, 0, j] = np.linalg.solve(self.k - w * w * self.m + 1j * w * self.c, [1.0, 0])
        return out


class TenModes:
    """10 modes, 3 outputs, one input; modal constants scaled so every peak is comparable."""

    def __init__(self, seed=3, freq_hz=(12.3, 27.0, 41.5, 55.2, 73.9, 88.1, 104.6, 131.0,
                                         152.7, 180.4),
                 damping=(0.001, 0.002, 0.005, 0.01, 0.02, 0.001, 0.003, 0.015, 0.008, 0.02)):
        self.freq_hz = np.array(freq_hz, dtype=float)
        self.damping = np.array(damping, dtype=float)
        rng = np.random.default_rng(seed)
        wn = 2 * np.pi * self.freq_hz
        n = len(wn)
        shapes = rng.uniform(0.5, 1.5, (3, n)) * rng.choice([-1.0, 1.0], (3, n))
        shapes[0] = np.abs(shapes[0])  # driving point: positive modal constants
        # peak of mode r about shapes * 1e-6 m/N: constant = peak * 2 zeta wn^2
        self.modal_constants = 1e-6 * shapes * (2 * self.damping * wn ** 2)[None, :]
        self.poles = wn * (-self.damping + 1j * np.sqrt(1 - self.damping ** 2))

    def frf(self, freq):
        """(3, 1, F) receptance [m/N]."""
        w = 2 * np.pi * np.asarray(freq)[None, :]
        wn, zeta = 2 * np.pi * self.freq_hz[:, None], self.damping[:, None]
        den = wn ** 2 - w ** 2 + 2j * zeta * wn * w
        return (self.modal_constants @ (1.0 / den))[:, None, :]


def multisine(period_steps, bins, rms=1.0):
    """One period of a multisine with Schroeder phases on DFT ``bins``, scaled to ``rms`` [N]."""
    bins = np.asarray(bins)
    k = np.arange(1, len(bins) + 1)
    spectrum = np.zeros(period_steps // 2 + 1, dtype=complex)
    spectrum[bins] = np.exp(-1j * np.pi * k * (k - 1) / len(bins))
    x = np.fft.irfft(spectrum, n=period_steps)
    return x * rms / np.sqrt(np.mean(x ** 2))


def periodic_response(system, u_period, dt, n_periods, noise_rel, rng):
    """
    Tiled input and the exact periodic output (plus white output noise) of ``system``.

    Returns
    -------
    u : (n_periods * P,) ndarray
    y : (No, n_periods * P) ndarray
        Noise standard deviation ``noise_rel * RMS`` of each noise-free output.
    """
    p = len(u_period)
    freq = np.fft.rfftfreq(p, dt)
    spec_u = np.fft.rfft(u_period)
    h = np.zeros((system.frf([1.0]).shape[0], len(freq)), dtype=complex)
    excited = np.abs(spec_u) > 1e-9 * np.abs(spec_u).max()
    h[:, excited] = system.frf(freq[excited])[:, 0, :]
    y_period = np.fft.irfft(h * spec_u[None, :], n=p, axis=1)
    y = np.tile(y_period, (1, n_periods))
    sigma = noise_rel * np.sqrt(np.mean(y_period ** 2, axis=1, keepdims=True))
    return np.tile(u_period, n_periods), y + sigma * rng.standard_normal(y.shape)
