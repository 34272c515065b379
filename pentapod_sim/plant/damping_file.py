"""
Calibrated modal damping: the file ``calibrate`` writes and config/reduction.yaml names.

``damping_file`` in reduction.yaml (relative to that file's folder) replaces ``damping_ratio``
and ``damping_groups``: each plant mode whose natural frequency lies within
``match_tolerance`` (relative) of a paired mode of the file gets that mode's measured ratio;
every other mode gets the fill: the ratio of the band it lies in, else the Rayleigh fit
``zeta(omega) = alpha / (2 omega) + beta omega / 2``, else ``default_ratio``.

The paired frequencies are the model's (those of the modes that were calibrated), so a file
applies to the model and position it was calibrated on; another position's modes shift and
are filled. The schema (:mod:`pentapod_sim.schema`) gives every key with its unit.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math
import os
from pathlib import Path

import numpy as np
import numpy.typing as npt
import yaml

from pentapod_sim.errors import ConfigError
from pentapod_sim.plant.config import DampingGroup
from pentapod_sim.schema import internal, load, NON_NEGATIVE, POSITIVE, spec

#: Default relative frequency tolerance between a plant mode and a paired mode of the file.
MATCH_TOLERANCE = 0.005


@dataclass(frozen=True)
class PairedMode:
    """A model mode paired with a measured one, and what the pairing rests on."""

    f_hz: float = spec('Hz', POSITIVE, description='natural frequency of the model mode')
    ratio: float = spec('-', POSITIVE, description='measured modal damping ratio')
    measured_f_hz: float | None = spec('Hz', POSITIVE, default=None,
                                       description='natural frequency of the measured mode')
    mac: float | None = spec('-', NON_NEGATIVE, default=None, bounds=(0.0, 1.0),
                             description='MAC of the pair at the measured DOFs')


@dataclass(frozen=True)
class Rayleigh:
    """Rayleigh damping ``zeta(omega) = alpha / (2 omega) + beta omega / 2``."""

    alpha: float = spec('1/s', description='mass-proportional coefficient')
    beta: float = spec('s', description='stiffness-proportional coefficient')

    def ratio(self, omega: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Damping ratio [-] at angular frequencies ``omega`` [rad/s]."""
        omega = np.asarray(omega, dtype=float)
        return self.alpha / (2.0 * omega) + self.beta * omega / 2.0


@dataclass(frozen=True)
class DampingFile:
    """Settings of a calibrated damping file (module docstring)."""

    modes: tuple[PairedMode, ...] = spec(description='paired modes and their measured ratios')
    rayleigh: Rayleigh | None = spec(default=None, description='fill of the unpaired modes')
    bands: tuple[DampingGroup, ...] = spec(default=(), description='fill ratios per band')
    default_ratio: float | None = spec('-', POSITIVE, default=None,
                                       description='fill outside the bands without Rayleigh')
    match_tolerance: float = spec('-', POSITIVE, default=MATCH_TOLERANCE, bounds=(0.0, 0.1),
                                  description='relative frequency tolerance of a match')
    measured: str = spec(default='', description='the measurement it was calibrated on')
    model: str = spec(default='', description='the model it was calibrated on')
    source: str = internal()

    def __post_init__(self) -> None:
        if self.rayleigh is None and self.default_ratio is None:
            raise ConfigError('give rayleigh or default_ratio: the fill of modes outside the '
                              'paired modes and bands')

    def ratios(self, frequencies_hz: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Damping ratio [-] of every mode of natural frequencies ``frequencies_hz`` [Hz]."""
        freq = np.asarray(frequencies_hz, dtype=float)
        omega = 2.0 * np.pi * freq
        if self.rayleigh is not None:
            zeta = self.rayleigh.ratio(np.where(omega > 0, omega, np.nan))
        else:
            zeta = np.full(freq.shape, float(self.default_ratio or 0.0))
        for band in self.bands:
            zeta[(freq >= band.f_min) & (freq < band.f_max)] = band.ratio
        for mode in self.modes:
            near = np.abs(freq - mode.f_hz) <= self.match_tolerance * mode.f_hz
            if near.any():
                zeta[np.flatnonzero(near)[np.argmin(np.abs(freq[near] - mode.f_hz))]] = \
                    mode.ratio
        bad = ~(np.isfinite(zeta) & (zeta > 0))
        if bad.any():
            raise ConfigError(f'{self.source}: the fill gives no positive damping ratio for the '
                              f'mode(s) at {", ".join(f"{f:.4g}" for f in freq[bad])} Hz')
        return zeta


def load_damping_file(path: str | os.PathLike[str]) -> DampingFile:
    """
    Read and validate a calibrated damping file.

    Raises
    ------
    ConfigError
        Naming the file, the key path and the bad value.
    """
    return replace(load(DampingFile, path), source=str(path))


def write_damping_file(path: str | os.PathLike[str], data: DampingFile, header: str = '') -> Path:
    """Write ``data`` as YAML (exact floats; ``header`` as comment lines on top)."""
    def clean(obj: object) -> object:
        if isinstance(obj, dict):
            return {k: clean(v) for k, v in obj.items() if v is not None and v != ()}
        if isinstance(obj, (list, tuple)):
            return [clean(v) for v in obj]
        return float(obj) if isinstance(obj, (float, np.floating)) and math.isfinite(obj) else obj
    text: dict[str, object] = {'modes': [vars(m) for m in data.modes]}
    if data.rayleigh is not None:
        text['rayleigh'] = vars(data.rayleigh)
    if data.bands:
        text['bands'] = [vars(b) for b in data.bands]
    for key in ('default_ratio', 'match_tolerance', 'measured', 'model'):
        text[key] = getattr(data, key)
    comment = ''.join(f'# {line}\n' for line in header.splitlines())
    path = Path(path)
    path.write_text(comment + yaml.safe_dump(clean(text), sort_keys=False), encoding='utf-8')
    return path
