"""
Study configuration (config/study.yaml): schema and validation.

The file's schema (:mod:`pentapod_sim.schema`, the validation style of every configuration
file) is :class:`StudyFile` with its sections; the study reads the flat :class:`StudyConfig`
made from it. Unknown keys are refused naming the closest known one; missing keys, wrong
types, values out of range, unknown positions and scenarios are refused naming the file, the
key and the value.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pentapod_sim.errors import ConfigError
from pentapod_sim.fe.machine_data import load_positions
from pentapod_sim.machining.materials import load_machining
from pentapod_sim.parameters import sample_time
from pentapod_sim.paths import config_dir
from pentapod_sim.plant.config import FrequencyGrid
from pentapod_sim.scenario.files import scenario_names
from pentapod_sim.schema import (
    build,
    check_choice,
    closest,
    NON_NEGATIVE,
    POSITIVE,
    read_mapping,
    spec,
)
from pentapod_sim.sim.stability import POLICIES

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
        Peak of the multisine TCP force of the FRF runs [N].
    band : tuple of float
        Band of its lines [Hz].
    period : float
        Its period [s] (line spacing 1 / period).
    periods : int
        Periods averaged per FRF run.
    settle_periods : int
        Periods run before them and discarded (the laws' own start transient).
    f_max : float
        Upper frequency of plots and tables [Hz].
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
    check_f_min : float
        Lowest cut-off of the truncation check's model [Hz] (at least 2x the sample rate).
    check_policy : str
        ``refuse`` or ``warn`` for a loop that is stable only thanks to truncation.
    pma_band : tuple of float
        Band of the worst-case PMA stroke and force [Hz].
    pma_frequencies : tuple of float
        Frequencies of the reported PMA stroke and force [Hz].
    pma_highpass_hz : float
        Corner of the high-pass PMA variant [Hz].
    damping_scenarios : tuple of str
        Scenarios of the damping runs (multisine, modal identification), per position; those
        not among ``scenarios`` are not run.
    damping_band : tuple of float
        Band of the multisine lines and of the identification [Hz].
    damping_period : float
        Multisine period [s] (line spacing 1 / period).
    damping_amplitude : float
        Peak of the multisine force [N].
    damping_periods : int
        Periods averaged after settling.
    damping_start : str
        ``'steady'`` (from the loop's periodic steady state) or ``'rest'``.
    damping_time_constants : float
        Settling time in decay time constants of the slowest dominant mode of the loop.
    machining_operations : tuple of str
        Operations of config/machining.yaml whose stability lobes the study draws; the first
        sets the summary's stable depth gain and the cutting runs.
    cutting_runs : tuple of str
        Scenarios cut on the testbed at every position at 0.8x and 1.2x of the predicted
        limiting depth (empty: none); those not among ``scenarios`` are not run.
    """

    positions: tuple[str, ...]
    scenarios: tuple[str, ...]
    sample_rate: float
    direction: str
    amplitude: float
    band: tuple[float, ...]
    period: float
    periods: int
    settle_periods: int
    f_max: float
    freq_grid: tuple[float, float, int]
    pma_force_amplitude: float
    step_position: str
    step_amplitude: float
    step_duration: float
    check_f_min: float
    check_policy: str
    pma_band: tuple[float, ...]
    pma_frequencies: tuple[float, ...]
    pma_highpass_hz: float
    damping_scenarios: tuple[str, ...]
    damping_band: tuple[float, ...]
    damping_period: float
    damping_amplitude: float
    damping_periods: int
    damping_start: str
    damping_time_constants: float
    machining_operations: tuple[str, ...]
    cutting_runs: tuple[str, ...]

    @property
    def dt(self) -> float:
        """Sample time [s] of every run (:func:`pentapod_sim.parameters.sample_time`)."""
        return sample_time(self.sample_rate)

    @property
    def duration(self) -> float:
        """Simulated time of an FRF run [s]: its settling and averaged periods."""
        return (self.settle_periods + self.periods) * self.period


@dataclass(frozen=True)
class TruncationCheck:
    """Truncation check of every sampled loop (:mod:`pentapod_sim.sim.stability`)."""

    f_min: float = spec('Hz', POSITIVE, description="lowest cut-off of the check model's "
                        'modes (at least 2x the sample rate is used)')
    policy: str = spec(choices=POLICIES, description='what a loop stable only thanks to '
                       'truncation does')


@dataclass(frozen=True)
class PmaRequirements:
    """PMA requirements at stated frequencies and in a stated band."""

    band: tuple[float, ...] = spec('Hz', POSITIVE, length=2,
                                   description='band of the worst-case stroke and force')
    frequencies: tuple[float, ...] = spec('Hz', POSITIVE, min_length=1,
                                          description='frequencies of the reported values')
    highpass_hz: float = spec('Hz', POSITIVE, description='corner of the high-pass variant')

    def __post_init__(self) -> None:
        if not self.band[0] < self.band[1]:
            raise ConfigError(f'pma_requirements.band = {list(self.band)} Hz: must satisfy '
                              'low < high')


@dataclass(frozen=True)
class Excitation:
    """Periodic multisine force at the TCP of the FRF runs, from the periodic steady state."""

    direction: str = spec(choices=AXES, description='TCP direction excited and measured')
    amplitude: float = spec('N', POSITIVE, description='peak of the multisine force')
    band: tuple[float, ...] = spec('Hz', POSITIVE, length=2, description='band of the lines')
    period: float = spec('s', POSITIVE, description='multisine period (line spacing 1 / '
                         'period)')
    periods: int = spec('-', POSITIVE, description='periods averaged')
    settle_periods: int = spec('-', NON_NEGATIVE, description='periods run before them and '
                               'discarded')


@dataclass(frozen=True)
class Analysis:
    """Plots and tables."""

    f_max: float = spec('Hz', POSITIVE, description='upper end of plots and tables')


@dataclass(frozen=True)
class StepResponse:
    """PMA step-response run."""

    position: str = spec(description='position of the step-response runs')
    amplitude: float = spec('N', POSITIVE, description='step force at the TCP')
    duration: float = spec('s', POSITIVE, description='length of the step-response runs')


@dataclass(frozen=True)
class DampingRuns:
    """Damping per mode measured on the testbed: multisine runs identified from their bags."""

    scenarios: tuple[str, ...] = spec(min_length=1, description='scenarios of the damping '
                                      'runs (each at every position)')
    band: tuple[float, ...] = spec('Hz', POSITIVE, length=2,
                                   description='multisine lines and identification band')
    period: float = spec('s', POSITIVE, description='multisine period (line spacing 1 / '
                         'period)')
    amplitude: float = spec('N', POSITIVE, description='peak of the multisine force')
    periods: int = spec('-', POSITIVE, description='periods averaged after settling')
    time_constants: float = spec('-', POSITIVE, description='settling time in decay time '
                                 'constants of the slowest dominant mode of the loop (start: '
                                 'rest)')
    start: str = spec(choices=('steady', 'rest'), default='steady',
                      description="steady: each run starts at its loop's periodic steady state "
                      "and settles excitation.settle_periods periods (the laws' own start); "
                      'rest: from rest, settled time_constants decay times')


@dataclass(frozen=True)
class MachiningStudy:
    """Stability lobes of every scenario and recorded cuts that check them."""

    operations: tuple[str, ...] = spec(min_length=1, description='operations of config/'
                                       'machining.yaml; the first sets the stable depth gain '
                                       'and the cutting runs')
    cutting_runs: tuple[str, ...] = spec(description='scenarios cut on the testbed at 0.8x and '
                                         '1.2x of the predicted limit, at every position (those '
                                         'not among scenarios are not run)')


@dataclass(frozen=True)
class StudyFile:
    """config/study.yaml; see that file for the meaning of each key."""

    positions: tuple[str, ...] = spec(min_length=1, description='positions of config/positions'
                                      '.yaml')
    scenarios: tuple[str, ...] = spec(min_length=1, description='scenarios, baseline first')
    sample_rate: float = spec('Hz', POSITIVE, description='plant sample rate of every run')
    excitation: Excitation = spec(description='excitation of the FRF runs')
    analysis: Analysis = spec(description='FRF estimation from the bags')
    frequency: FrequencyGrid = spec(description='frequencies of the analytic FRFs')
    pma_force_amplitude: float = spec('N', POSITIVE,
                                      description='harmonic TCP force of the PMA requirements')
    step_response: StepResponse = spec(description='PMA step-response run')
    truncation_check: TruncationCheck = spec(description='truncation check of the loops')
    pma_requirements: PmaRequirements = spec(description='PMA requirements')
    damping: DampingRuns = spec(description='damping runs (multisine, modal identification)')
    machining: MachiningStudy = spec(description='stability lobes and recorded cuts')

    def __post_init__(self) -> None:
        exc, fs = self.excitation, self.sample_rate
        if self.scenarios[0] != 'baseline':
            raise ConfigError(f'scenarios[0] = {self.scenarios[0]!r}: the scenarios must start '
                              'with baseline')
        lo, hi = exc.band
        if not 0 < lo < hi < fs / 2:
            raise ConfigError(f'excitation.band = {list(exc.band)} Hz: must satisfy 0 < low < '
                              f'high < sample_rate / 2 = {fs / 2:g} Hz')
        lo, hi = self.damping.band
        if not 0 < lo < hi < fs / 2:
            raise ConfigError(f'damping.band = {list(self.damping.band)} Hz: must satisfy 0 < '
                              f'low < high < sample_rate / 2 = {fs / 2:g} Hz')


#: Key path in the file of each :class:`StudyConfig` attribute.
FILE_KEYS = {'positions': 'positions', 'scenarios': 'scenarios', 'sample_rate': 'sample_rate',
             'direction': 'excitation.direction', 'amplitude': 'excitation.amplitude',
             'band': 'excitation.band', 'period': 'excitation.period',
             'periods': 'excitation.periods',
             'settle_periods': 'excitation.settle_periods', 'f_max': 'analysis.f_max',
             'freq_grid': 'frequency', 'pma_force_amplitude': 'pma_force_amplitude',
             'step_position': 'step_response.position',
             'step_amplitude': 'step_response.amplitude',
             'step_duration': 'step_response.duration',
             'check_f_min': 'truncation_check.f_min',
             'check_policy': 'truncation_check.policy',
             'pma_band': 'pma_requirements.band',
             'pma_frequencies': 'pma_requirements.frequencies',
             'pma_highpass_hz': 'pma_requirements.highpass_hz',
             'damping_scenarios': 'damping.scenarios', 'damping_band': 'damping.band',
             'damping_period': 'damping.period', 'damping_amplitude': 'damping.amplitude',
             'damping_periods': 'damping.periods',
             'damping_start': 'damping.start',
             'damping_time_constants': 'damping.time_constants',
             'machining_operations': 'machining.operations',
             'cutting_runs': 'machining.cutting_runs'}


def _get(obj: Any, key_path: str) -> Any:
    for key in key_path.split('.'):
        obj = getattr(obj, key)
    if isinstance(obj, FrequencyGrid):
        return (obj.f_min, obj.f_max, obj.n_points)
    return obj


def _set(doc: dict[str, Any], key_path: str, value: Any) -> None:
    *parents, last = key_path.split('.')
    for key in parents:                 # the file was checked: its sections are mappings
        doc = doc[key]
    if last == 'frequency' and isinstance(value, (list, tuple)) and len(value) == 3:
        value = dict(zip(('f_min', 'f_max', 'n_points'), value))
    elif isinstance(value, tuple):
        value = list(value)
    doc[last] = value


def _check_names(study: StudyFile, source: str) -> None:
    """Positions and scenarios must exist (positions.yaml, config/scenarios)."""
    positions, scenarios = sorted(load_positions()), scenario_names()
    named = [(f'positions[{i}]', p) for i, p in enumerate(study.positions)]
    named.append(('step_response.position', study.step_response.position))
    try:
        for key, name in named:
            check_choice(name, positions, key, 'position of positions.yaml')
        for i, name in enumerate(study.scenarios):
            check_choice(name, scenarios, f'scenarios[{i}]', 'scenario of config/scenarios')
        for i, name in enumerate(study.damping.scenarios):
            check_choice(name, scenarios, f'damping.scenarios[{i}]',
                         'scenario of config/scenarios')
        for i, name in enumerate(study.machining.cutting_runs):
            check_choice(name, scenarios, f'machining.cutting_runs[{i}]',
                         'scenario of config/scenarios')
        table = load_machining()
        for i, name in enumerate(study.machining.operations):
            check_choice(name, sorted(table.operations), f'machining.operations[{i}]',
                         'operation of config/machining.yaml')
    except ConfigError as err:
        raise ConfigError(f'{source}: {err}') from None


def load_study_config(path: str | Path | None = None, **overrides: Any) -> StudyConfig:
    """
    Read and validate a study configuration.

    Parameters
    ----------
    path : str or Path, optional
        YAML file; default :func:`default_path`.
    **overrides
        Attribute values of :class:`StudyConfig` that replace the file's (e.g. from the CLI),
        checked like the file's values.

    Raises
    ------
    ConfigError
        Naming the file (and the overrides), the key and its value.
    """
    path = Path(path) if path else default_path()
    doc = read_mapping(path)
    source = str(path)
    build(StudyFile, doc, source)                         # the file alone is valid
    overrides = {k: v for k, v in overrides.items() if v is not None}
    if overrides:
        doc = copy.deepcopy(doc)
        for name, value in overrides.items():
            if name not in FILE_KEYS:
                near = closest(name, FILE_KEYS)
                raise ConfigError(f'unknown study setting {name!r}'
                                  f'{f"; did you mean {near!r}?" if near else ""}')
            _set(doc, FILE_KEYS[name], value)
        source = f'{path} with {", ".join(f"{k}={v!r}" for k, v in overrides.items())}'
    study = build(StudyFile, doc, source)
    _check_names(study, source)
    return StudyConfig(**{name: _get(study, key) for name, key in FILE_KEYS.items()})
