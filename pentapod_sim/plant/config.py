"""
Reduction configuration (``config/reduction.yaml``): ports, modes, relevance rules, damping.

The file's schema (:mod:`pentapod_sim.schema`): every key is a field below with its unit, rule
and meaning. :func:`load_reduction_config` refuses unknown keys (naming the closest known one),
missing keys, unknown port names and values out of range, each error naming the file.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import os
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from pentapod_sim.errors import ConfigError
from pentapod_sim.paths import config_dir
from pentapod_sim.plant.ports import INPUT_NAMES, OUTPUT_NAMES
from pentapod_sim.schema import build, check_choice, internal, load, NON_NEGATIVE, POSITIVE, spec

#: Relevance measures: dc gain ``c b / omega^2`` or resonance peak ``c b / (2 zeta omega^2)``.
MEASURES = ('dc', 'resonance')
#: Unit of a relevance limit: that of the gains of the pairs it names, e.g. m/N.
PAIR_UNIT = 'unit of the pair'


def _all(known: tuple[str, ...]) -> Callable[[Any], Any]:
    """YAML ``all`` stands for every port name."""
    return lambda value: list(known) if value == 'all' else value


def _ports(known: tuple[str, ...], what: str) -> Any:
    return spec(choices=known, min_length=1, pre=_all(known),
                description=f'{what} port names or all')


@dataclass(frozen=True)
class FrequencyGrid:
    """Evenly spaced frequencies from ``f_min`` to ``f_max`` [Hz], ``n_points`` of them."""

    f_min: float = spec('Hz', NON_NEGATIVE, description='lowest frequency')
    f_max: float = spec('Hz', POSITIVE, description='highest frequency')
    n_points: int = spec('-', POSITIVE, description='number of frequencies')

    def __post_init__(self) -> None:
        if not self.f_min < self.f_max:
            raise ConfigError(f'f_min = {self.f_min!r} Hz must be < f_max = {self.f_max!r} Hz')
        if self.n_points < 2:
            raise ConfigError(f'n_points = {self.n_points!r} must be >= 2')

    def grid(self) -> np.ndarray:
        """The frequencies [Hz]."""
        return np.linspace(self.f_min, self.f_max, self.n_points)


@dataclass(frozen=True)
class RelevanceRule:
    """
    One relevance criterion: keep the modes that matter for the (output, input) pairs named.

    Exactly one of ``abs_limit``, ``rel_limit`` and ``count`` is given
    (:func:`pentapod_sim.plant.reduction.select_modes`).
    """

    inputs: tuple[str, ...] = _ports(INPUT_NAMES, 'input')
    outputs: tuple[str, ...] = _ports(OUTPUT_NAMES, 'output')
    abs_limit: float | None = spec(PAIR_UNIT, POSITIVE, default=None,
                                   description='least absolute gain of a kept mode')
    rel_limit: float | None = spec('-', POSITIVE, default=None, bounds=(0.0, 1.0),
                                   closed=(False, False),
                                   description="least share of the pair's summed |gain|")
    count: int | None = spec('-', POSITIVE, default=None,
                             description='number of most relevant modes kept')
    measure: str = spec(default='dc', choices=MEASURES,
                        description='dc: c b / omega^2; resonance: c b / (2 zeta omega^2)')

    def __post_init__(self) -> None:
        given = [k for k in ('abs_limit', 'rel_limit', 'count') if getattr(self, k) is not None]
        if len(given) != 1:
            raise ConfigError(f'give exactly one of abs_limit, rel_limit, count; got '
                              f'{", ".join(given) or "none"}')

    @property
    def criterion(self) -> dict[str, float | int]:
        """The one criterion as keyword arguments of ``select_modes``."""
        return {k: getattr(self, k) for k in ('abs_limit', 'rel_limit', 'count')
                if getattr(self, k) is not None}


@dataclass(frozen=True)
class DampingGroup:
    """
    Modal damping ratio of the modes in a frequency band ``f_min <= f < f_max`` [Hz].

    Models a machine whose dominant modes are more damped than the uniform ``damping_ratio``
    (the reference paper reports 2-12x more than 0.1 % for the real machine's dominant modes).
    """

    f_min: float = spec('Hz', NON_NEGATIVE, description='lowest natural frequency of the group')
    f_max: float = spec('Hz', POSITIVE, description='natural frequencies below this one')
    ratio: float = spec('-', NON_NEGATIVE, description='modal damping ratio of the group')

    def __post_init__(self) -> None:
        if not self.f_min < self.f_max:
            raise ConfigError(f'damping group: f_min = {self.f_min!r} Hz must be < f_max = '
                              f'{self.f_max!r} Hz')


@dataclass(frozen=True)
class ReductionConfig:
    """Settings of config/reduction.yaml; see that file for the meaning of each key."""

    inputs: tuple[str, ...] = _ports(INPUT_NAMES, 'input')
    outputs: tuple[str, ...] = _ports(OUTPUT_NAMES, 'output')
    modes_f_max: float = spec('Hz', POSITIVE, description='modes below this frequency')
    relevance: tuple[RelevanceRule, ...] = spec(min_length=1,
                                                description='relevance criteria (united)')
    static_correction: bool = spec(description='residual flexibility of dropped modes as D')
    damping_ratio: float | tuple[float, ...] = spec(
        '-', NON_NEGATIVE, description='modal damping ratio, one or one per mode')
    frequency: FrequencyGrid = spec(description='FRF frequencies')
    sample_rate: float = spec('Hz', POSITIVE, description='sample rate of the discrete plant')
    positions: tuple[str, ...] = spec(min_length=1,
                                      description='positions of the CLI reports and plots')
    report_pair: tuple[str, ...] = spec(length=2, description='(output, input) of the reports')
    damping_groups: tuple[DampingGroup, ...] = spec(
        default=(), description='damping ratios of modes in frequency bands (override)')
    chord_position: float = spec('-', NON_NEGATIVE, default=0.5, bounds=(0.0, 1.0),
                                 description='chord point of the chord ports, BP (0) to WP (1)')
    damping_file: str | None = spec(default=None, description='calibrated modal damping '
                                    '(calibrate writes it); replaces damping_ratio and groups')
    source: str = internal()

    def __post_init__(self) -> None:
        if self.damping_file is not None and self.damping_groups:
            raise ConfigError('damping_file replaces damping_groups: give one of them')
        bands = sorted((g.f_min, g.f_max) for g in self.damping_groups)
        for (lo1, hi1), (lo2, _) in zip(bands, bands[1:]):
            if lo2 < hi1:
                raise ConfigError(f'damping_groups overlap: [{lo1}, {hi1}) Hz and from {lo2} Hz')
        check_choice(self.report_pair[0], OUTPUT_NAMES, 'report_pair[0]', 'output port')
        check_choice(self.report_pair[1], INPUT_NAMES, 'report_pair[1]', 'input port')
        for i, rule in enumerate(self.relevance):
            for kind, names in (('inputs', rule.inputs), ('outputs', rule.outputs)):
                for k, name in enumerate(names):
                    if name not in getattr(self, kind):
                        raise ConfigError(f'relevance[{i}].{kind}[{k}] = {name!r}: not among '
                                          f'the {kind} of the plant')


def default_path() -> Path:
    """config/reduction.yaml of :func:`pentapod_sim.paths.config_dir`."""
    return config_dir() / 'reduction.yaml'


def load_reduction_config(path: str | os.PathLike[str] | None = None) -> ReductionConfig:
    """
    Read and validate config/reduction.yaml (or ``path``).

    Raises
    ------
    ConfigError
        Naming the file, the key path and the bad value (or the closest known key).
    """
    path = Path(path) if path is not None else default_path()
    return replace(load(ReductionConfig, path), source=str(path))


def damping_file_path(cfg: ReductionConfig) -> Path | None:
    """The config's ``damping_file``, relative to the config file's folder (None if unset)."""
    if cfg.damping_file is None:
        return None
    return Path(cfg.source).parent / cfg.damping_file if cfg.source else Path(cfg.damping_file)


def relevance_rule(rule: RelevanceRule | Mapping[str, Any]) -> RelevanceRule:
    """A :class:`RelevanceRule`, validated from a mapping with the keys of the file's rules."""
    return rule if isinstance(rule, RelevanceRule) else build(RelevanceRule, dict(rule),
                                                             'relevance rule')
