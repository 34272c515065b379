"""
The judge's settings and thresholds (config/judge.yaml): schema, defaults, overrides.

Validated like every configuration file (:mod:`pentapod_sim.schema`): an unknown key is
refused naming the closest known one, a bad value naming the file, the key path and the value.
A user copies config/judge.yaml, changes what matters to them (thresholds, force limit,
directions) and passes it with ``judge --config FILE``; options of the command line override
single keys (checked the same way).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pentapod_sim.errors import ConfigError
from pentapod_sim.paths import config_dir
from pentapod_sim.schema import build, NON_NEGATIVE, POSITIVE, read_mapping, spec

AXES = ('x', 'y', 'z')


def default_path() -> Path:
    """config/judge.yaml of the package's share folder."""
    return config_dir() / 'judge.yaml'


@dataclass(frozen=True)
class Multisine:
    """The runs that measure compliance, damping, actuator demand and the machining verdict."""

    band: tuple[float, ...] = spec('Hz', POSITIVE, length=2,
                                   description='lines of the Schroeder multisine at the TCP')
    period: float = spec('s', POSITIVE, description='period (line spacing 1 / period)')
    amplitude: float = spec('N', POSITIVE, description='peak force of the multisine')
    periods: int = spec('-', POSITIVE, description='periods averaged after settling (>= 2)')
    time_constants: float = spec('-', POSITIVE, description='settling time in decay times of '
                                 "the slowest of the baseline's strongest modes")
    settle_modes: int = spec('-', POSITIVE, description='strongest modes of the baseline in '
                             'TCP dd whose decay sets the settling time')

    def __post_init__(self) -> None:
        if not self.band[0] < self.band[1]:
            raise ConfigError(f'band = {list(self.band)} Hz must increase')
        if self.periods < 2:
            raise ConfigError(f'periods = {self.periods}: at least 2 are averaged (the '
                              'settling error compares them)')


@dataclass(frozen=True)
class Identification:
    """Modal identification of the multisine runs (pLSCF + LSFD)."""

    modes: int = spec('-', POSITIVE, description='dominant modes per direction in the tables')
    max_order: int = spec('-', POSITIVE, description='highest pLSCF model order')
    pair_tolerance: float = spec('-', POSITIVE, bounds=(0.0, 0.5), description='a mode of a '
                                 "controller without a linear model pairs with the baseline's "
                                 'nearest mode within this relative frequency distance')


@dataclass(frozen=True)
class Robustness:
    """The run that identifies the controller in the loop, and the stability check."""

    amplitude: float = spec('N or N m', POSITIVE, description='RMS of the white noise on '
                            "each port the controller answers (and its sensors' collocated "
                            'inputs)')
    duration: float = spec('s', POSITIVE, description='length of the identification run')
    nperseg: int = spec('-', POSITIVE, description='samples per Welch segment of the '
                        "controller's FRF")
    check_f_min: float = spec('Hz', POSITIVE, description='the check model holds every FE mode '
                              'below max(check_f_min, 2 sample_rate)')


@dataclass(frozen=True)
class Thresholds:
    """Pass/fail limits of the summary table."""

    damping_min_gain: float = spec('-', NON_NEGATIVE, description='every dominant mode of '
                                   'every direction keeps at least this times its baseline '
                                   'damping ratio')
    peak_reduction_min: float = spec('-', NON_NEGATIVE, description='baseline over controller '
                                     'TCP compliance peak, every direction')
    rms_reduction_min: float = spec('-', NON_NEGATIVE, description='baseline over controller '
                                    'TCP compliance RMS, every direction')
    best_peak_reduction_min: float = spec('-', NON_NEGATIVE, description='the largest peak '
                                          'reduction over the directions')
    stable_depth_gain_min: float = spec('-', NON_NEGATIVE, description='minimum stable depth '
                                        'of cut over the baseline one')
    force_limit: float = spec('N or N m', POSITIVE, description="the actuator's force limit "
                              'on every port')
    force_limit_share_max: float = spec('-', NON_NEGATIVE, bounds=(0.0, 1.0), description=(
        'largest share of the steps at which a port reaches force_limit'))
    margin_min: float = spec('-', NON_NEGATIVE, description='return-difference margin min '
                             'sigma(I - L) of the loop on the check model')
    coherence_min: float = spec('-', NON_NEGATIVE, bounds=(0.0, 1.0), description='lowest '
                                "multiple coherence of the controller's identified FRF")
    stable_with_delay: bool = spec(description='the loop on the check model must stay stable '
                                   'with one more sample of delay')
    rejected_max: int = spec('-', NON_NEGATIVE, description='answers the plant rejected')
    missing_max: int = spec('-', NON_NEGATIVE, description='steps missing from a recording')


@dataclass(frozen=True)
class JudgeConfig:
    """config/judge.yaml."""

    positions: tuple[str, ...] = spec(min_length=1, description='machine positions '
                                      '(config/positions.yaml)')
    sample_rate: float = spec('Hz', POSITIVE, description='plant sample rate of every run')
    reference: str = spec(description='scenario whose controller fills the reference column '
                          "(a shipped name or a file); '' for none")
    directions: tuple[str, ...] = spec(min_length=1, choices=AXES,
                                       description='TCP directions excited and judged')
    operation: str = spec(description='milling operation of config/machining.yaml')
    multisine: Multisine = spec(description='multisine runs')
    identification: Identification = spec(description='modal identification')
    robustness: Robustness = spec(description='identification of the controller, loop check')
    thresholds: Thresholds = spec(description='pass/fail limits')

    def __post_init__(self) -> None:
        if len(set(self.directions)) != len(self.directions):
            raise ConfigError(f'directions = {list(self.directions)} repeat a direction')

    @property
    def dt(self) -> float:
        """Sample time [s]."""
        return 1.0 / self.sample_rate


#: Command-line overrides: option name -> key of the file.
OVERRIDES = ('positions', 'sample_rate', 'reference', 'directions')


def load_judge_config(path: str | Path | None = None, **overrides: Any) -> JudgeConfig:
    """
    Read and validate the judge's settings; ``overrides`` replace top-level keys (checked).

    Raises
    ------
    ConfigError
        Naming the file (and the overrides), the key and its value.
    """
    path = Path(path) if path else default_path()
    doc = read_mapping(path)
    build(JudgeConfig, doc, str(path))                    # the file alone is valid
    given = {k: v for k, v in overrides.items() if v is not None}
    for name in given:
        if name not in OVERRIDES:
            raise ConfigError(f'unknown judge setting {name!r}')
    if not given:
        return build(JudgeConfig, doc, str(path))
    doc = copy.deepcopy(doc)
    doc.update(given)
    return build(JudgeConfig, doc, f'{path} with '
                 + ', '.join(f'{k}={v!r}' for k, v in given.items()))
