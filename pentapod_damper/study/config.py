"""Study configuration (config/study.yaml): schema, defaults and validation."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from pentapod_sim.errors import ConfigError
from pentapod_sim.paths import config_dir

AXES = ('x', 'y', 'z')


def default_path() -> Path:
    """config/study.yaml of the package's share folder."""
    return config_dir() / 'study.yaml'


@dataclass(frozen=True)
class StudyConfig:
    """
    Settings of one study run (see config/study.yaml for meanings and units).

    Attributes
    ----------
    positions : tuple of str
        Position names of config/positions.yaml.
    scenarios : tuple of str
        Scenario names of config/scenarios, baseline first.
    sample_rate : float
        Plant sample rate [Hz].
    direction : str
        Excited and measured TCP direction (x, y or z).
    amplitude : float
        RMS of the random TCP force [N].
    band : tuple of float
        Band of the random force [Hz].
    duration : float
        Excited and recorded time per run [s].
    seed : int
        Random seed of the excitation.
    nperseg : int
        Welch segment length [samples].
    f_max : float
        Upper frequency of plots and tables [Hz].
    coherence_min : float
        Coherence above which measured and analytic FRFs are compared.
    freq_grid : tuple
        (f_min, f_max, n_points) of the analytic FRFs [Hz].
    pma_force_amplitude : float
        Harmonic TCP force amplitude for the PMA requirements [N].
    step_position : str
        Position of the PMA step-response runs.
    step_amplitude : float
        Step force [N].
    step_duration : float
        Length of the step-response runs [s].
    """

    positions: tuple
    scenarios: tuple
    sample_rate: float
    direction: str
    amplitude: float
    band: tuple
    duration: float
    seed: int
    nperseg: int
    f_max: float
    coherence_min: float
    freq_grid: tuple
    pma_force_amplitude: float
    step_position: str
    step_amplitude: float
    step_duration: float


def _get(doc: dict, key: str, kind: type, where: str = '') -> Any:
    name = f'{where}{key}'
    if key not in doc:
        raise ConfigError(f'study config: missing key {name!r}')
    value = doc[key]
    try:
        if kind is tuple:
            if not isinstance(value, (list, tuple)) or not value:
                raise TypeError
            return tuple(value)
        if kind is str and not isinstance(value, str):
            raise TypeError
        return kind(value)
    except (TypeError, ValueError):
        raise ConfigError(f'study config: {name} = {value!r} is not a valid '
                          f'{kind.__name__}') from None


def _positive(name: str, value: float) -> float:
    if not value > 0:
        raise ConfigError(f'study config: {name} = {value!r} must be > 0')
    return value


def load_study_config(path: str | Path | None = None, **overrides: Any) -> StudyConfig:
    """
    Read and validate a study configuration.

    Parameters
    ----------
    path : str or Path, optional
        YAML file; default :func:`default_path`.
    **overrides
        Attribute values of :class:`StudyConfig` that replace the file's (e.g. from the CLI).

    Raises
    ------
    ConfigError
        Naming the missing or invalid key and its value.
    """
    path = Path(path) if path else default_path()
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f'cannot read study config {path}: {err}') from None
    if not isinstance(doc, dict):
        raise ConfigError(f'study config {path} is not a mapping')
    exc = _get(doc, 'excitation', dict)
    ana = _get(doc, 'analysis', dict)
    freq = _get(doc, 'frequency', dict)
    step = _get(doc, 'step_response', dict)
    values = {
        'positions': _get(doc, 'positions', tuple), 'scenarios': _get(doc, 'scenarios', tuple),
        'sample_rate': _get(doc, 'sample_rate', float),
        'direction': _get(exc, 'direction', str, 'excitation.'),
        'amplitude': _get(exc, 'amplitude', float, 'excitation.'),
        'band': _get(exc, 'band', tuple, 'excitation.'),
        'duration': _get(exc, 'duration', float, 'excitation.'),
        'seed': _get(exc, 'seed', int, 'excitation.'),
        'nperseg': _get(ana, 'nperseg', int, 'analysis.'),
        'f_max': _get(ana, 'f_max', float, 'analysis.'),
        'coherence_min': _get(ana, 'coherence_min', float, 'analysis.'),
        'freq_grid': (_get(freq, 'f_min', float, 'frequency.'),
                   _get(freq, 'f_max', float, 'frequency.'),
                   _get(freq, 'n_points', int, 'frequency.')),
        'pma_force_amplitude': _get(doc, 'pma_force_amplitude', float),
        'step_position': _get(step, 'position', str, 'step_response.'),
        'step_amplitude': _get(step, 'amplitude', float, 'step_response.'),
        'step_duration': _get(step, 'duration', float, 'step_response.')}
    values.update({k: v for k, v in overrides.items() if v is not None})
    return _validated(StudyConfig(**values))


def _validated(cfg: StudyConfig) -> StudyConfig:
    for name in ('sample_rate', 'amplitude', 'duration', 'f_max', 'pma_force_amplitude',
                 'step_amplitude', 'step_duration'):
        _positive(name, getattr(cfg, name))
    if cfg.direction not in AXES:
        raise ConfigError(f'study config: excitation.direction = {cfg.direction!r} is not '
                          'one of x, y, z')
    if cfg.scenarios[0] != 'baseline':
        raise ConfigError(f'study config: scenarios must start with baseline, got '
                          f'{cfg.scenarios[0]!r}')
    lo, hi = (float(v) for v in cfg.band)
    if not 0 <= lo < hi < cfg.sample_rate / 2:
        raise ConfigError(f'study config: excitation.band = {list(cfg.band)} must satisfy '
                          f'0 <= low < high < sample_rate / 2 = {cfg.sample_rate / 2} Hz')
    if not 16 <= cfg.nperseg <= cfg.duration * cfg.sample_rate:
        raise ConfigError(f'study config: analysis.nperseg = {cfg.nperseg} must lie in '
                          f'[16, duration * sample_rate]')
    if not 0 < cfg.coherence_min < 1:
        raise ConfigError(f'study config: analysis.coherence_min = {cfg.coherence_min} '
                          'must lie in (0, 1)')
    return cfg
