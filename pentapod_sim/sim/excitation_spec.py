"""
Parameters of an excitation signal: the spec, its checks and its JSON form (stored in bags).

:class:`ExcitationSpec` holds what a user sets; :func:`check_spec` refuses a bad value with a
:class:`~pentapod_sim.errors.ConfigError` naming it. :func:`spec_to_dict` /
:func:`spec_from_dict` turn a spec into plain JSON-safe data and back (non-finite numbers
as the strings ``'inf'``, ``'-inf'``, ``'nan'``); :func:`spec_message` / :func:`parse_spec_message`
are the text the exciter node publishes once per run (docs/nodes.md) and the analysis reads
back from a bag (:mod:`pentapod_sim.analysis.bag.excitation_record`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
import json
import math
from typing import Any, Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import sample_time

KINDS = ('impulse', 'step', 'sine', 'chirp', 'random', 'multisine', 'periodic_chirp',
         'stepped_sine', 'none')
#: Kinds that repeat one period of ``period`` s (a whole number of samples).
PERIODIC_KINDS = ('multisine', 'periodic_chirp')
#: Shapes of the impulse (hammer) pulse over ``pulse_width`` (excitation_signals.pulse).
PULSE_SHAPES = ('rect', 'half_sine', 'hann')
#: Phases of the multisine lines: Schroeder (low crest factor), seeded uniform random, all 0.
PHASES = ('schroeder', 'random', 'zero')
#: Version of the JSON of :func:`spec_message`.
MESSAGE_FORMAT = 1


@dataclass
class ExcitationSpec:
    """
    Parameters of an excitation signal.

    Attributes
    ----------
    kind : str
        One of ``impulse`` (hammer: a ``pulse_shape`` pulse of peak ``amplitude`` over
        ``pulse_width``), ``step``, ``sine`` (at ``frequency``), ``chirp`` (linear sweep
        ``f_start`` -> ``f_end`` over ``duration``), ``random`` (Gaussian, band-limited to
        [f_start, f_end], RMS ``amplitude``, seeded), ``multisine`` (periodic, lines k/period
        in [f_start, f_end] or ``frequencies``, ``phases``, peak ``amplitude``),
        ``periodic_chirp`` (linear sweep f_start -> f_end within every ``period``),
        ``stepped_sine`` (per line: ``settle_time``, then ``periods_per_line`` whole periods),
        ``none``.
    amplitude : float
        Peak force [N] (RMS for random).
    direction : (3,) array_like
        Direction of the force in the machine frame (normalised here).
    frequency : float
        Sine frequency [Hz].
    f_start, f_end : float
        Band [Hz]: chirp start/end, random band edges, multisine and periodic-chirp band,
        stepped-sine lines when ``frequencies`` is empty.
    duration : float
        Length of the signal [s]; inf = endless (step, sine, impulse, periodic kinds,
        stepped sine: it ends after its last line).
    start_delay : float
        Time of the first sample of the signal [s].
    pulse_width : float
        Impulse length [s]; 0 = one sample.
    seed : int
        Seed of the random generator (random signal, random multisine phases).
    period : float
        Period of the periodic kinds [s]; a whole number of plant samples.
    phases : str
        Multisine phases, one of :data:`PHASES`.
    frequencies : list of float
        Multisine lines (multiples of 1/period) or stepped-sine frequencies [Hz]; empty: from
        the band (multisine: every multiple of 1/period, stepped sine: ``line_spacing``).
    line_spacing : float
        Stepped sine: spacing of the lines from f_start to f_end [Hz].
    settle_time : float
        Stepped sine: time at each line before its measurement window [s].
    periods_per_line : int
        Stepped sine: whole periods in each measurement window (the frequency is adjusted
        so that they span a whole number of samples).
    settle_periods : int
        Periodic kinds: leading periods the analysis discards (transient); does not change
        the signal.
    pulse_shape : str
        Impulse shape, one of :data:`PULSE_SHAPES`.
    """

    kind: str = 'impulse'
    amplitude: float = 100.0
    direction: npt.ArrayLike = field(default_factory=lambda: [1.0, 0.0, 0.0])
    frequency: float = 40.0
    f_start: float = 5.0
    f_end: float = 300.0
    duration: float = math.inf
    start_delay: float = 0.0
    pulse_width: float = 0.0
    seed: int = 0
    period: float = 1.0
    phases: str = 'schroeder'
    frequencies: list[float] = field(default_factory=list)
    line_spacing: float = 1.0
    settle_time: float = 1.0
    periods_per_line: int = 10
    settle_periods: int = 1
    pulse_shape: str = 'rect'


def _choice(name: str, value: str, choices: Sequence[str]) -> None:
    if value not in choices:
        raise ConfigError(f'excitation {name} {value!r} is not one of {", ".join(choices)}')


def check_spec(spec: ExcitationSpec, dt: float) -> None:
    """Raise ConfigError naming the first bad parameter of ``spec`` at sample time dt [s]."""
    _choice('kind', spec.kind, KINDS)
    _choice('pulse_shape', spec.pulse_shape, PULSE_SHAPES)
    _choice('phases', spec.phases, PHASES)
    if not np.isfinite(dt) or dt <= 0:
        raise ConfigError(f'sample time must be > 0 s, got {dt!r}')
    direction = np.asarray(spec.direction, dtype=float)
    if direction.shape != (3,) or not np.all(np.isfinite(direction)) or not direction.any():
        raise ConfigError(f'direction must be a non-zero 3-vector, got {spec.direction!r}')
    if not np.isfinite(spec.amplitude):
        raise ConfigError(f'amplitude must be finite [N], got {spec.amplitude!r}')
    if not spec.start_delay >= 0 or not np.isfinite(spec.start_delay):
        raise ConfigError(f'start_delay must be >= 0 s, got {spec.start_delay!r}')
    if not spec.duration > 0:
        raise ConfigError(f'duration must be > 0 s, got {spec.duration!r}')
    if not 0 <= spec.pulse_width < math.inf:
        raise ConfigError(f'pulse_width must be >= 0 s, got {spec.pulse_width!r}')
    if int(spec.settle_periods) != spec.settle_periods or spec.settle_periods < 0:
        raise ConfigError(f'settle_periods must be an integer >= 0, got {spec.settle_periods!r}')
    nyquist = 0.5 / dt
    if spec.kind == 'sine' and not 0 < spec.frequency < nyquist:
        raise ConfigError(f'frequency {spec.frequency} Hz must lie in (0, {nyquist}) Hz')
    if spec.kind in ('chirp', 'random') and not math.isfinite(spec.duration):
        raise ConfigError(f'a {spec.kind} excitation needs a finite duration [s]')
    if spec.kind in ('chirp', 'random', 'periodic_chirp') or (
            spec.kind in ('multisine', 'stepped_sine') and not len(spec.frequencies)):
        if not 0 <= spec.f_start < spec.f_end < nyquist:
            raise ConfigError(f'band f_start={spec.f_start}, f_end={spec.f_end} Hz must '
                              f'satisfy 0 <= f_start < f_end < {nyquist} Hz')
    if spec.kind in PERIODIC_KINDS:
        period_samples(spec.period, dt)
    if spec.kind in ('multisine', 'stepped_sine'):
        for f in spec.frequencies:
            if not 0 < f < nyquist:
                raise ConfigError(f'{spec.kind} frequency {f!r} Hz must lie in (0, {nyquist}) '
                                  'Hz')
    if spec.kind == 'stepped_sine':
        if not len(spec.frequencies) and not spec.line_spacing > 0:
            raise ConfigError(f'line_spacing must be > 0 Hz, got {spec.line_spacing!r}')
        if not 0 <= spec.settle_time < math.inf:
            raise ConfigError(f'settle_time must be >= 0 s, got {spec.settle_time!r}')
        if int(spec.periods_per_line) != spec.periods_per_line or spec.periods_per_line < 1:
            raise ConfigError('periods_per_line must be an integer >= 1, got '
                              f'{spec.periods_per_line!r}')


def period_samples(period: float, dt: float) -> int:
    """Samples per ``period`` [s] at dt [s]; ConfigError unless a whole number (>= 4)."""
    if not 0 < period < math.inf:
        raise ConfigError(f'period must be > 0 s, got {period!r}')
    exact = period / dt
    n = int(round(exact))
    if abs(exact - n) > 1e-9 * max(1.0, exact) or n < 4:
        raise ConfigError(f'period {period!r} s is not a whole number (>= 4) of samples of '
                          f'{dt!r} s ({exact:.6g} samples)')
    return n


# --- JSON form ---------------------------------------------------------------------------------

def _json_float(value: float) -> float | str:
    value = float(value)
    return value if math.isfinite(value) else str(value)   # 'inf', '-inf', 'nan'


def spec_to_dict(spec: ExcitationSpec) -> dict[str, Any]:
    """Plain, JSON-safe data of ``spec`` (floats; non-finite ones as 'inf', '-inf', 'nan')."""
    out: dict[str, Any] = {}
    for f in fields(ExcitationSpec):
        value = getattr(spec, f.name)
        if f.name in ('direction', 'frequencies'):
            out[f.name] = [_json_float(v) for v in np.asarray(value, dtype=float).ravel()]
        elif f.type == 'float':
            out[f.name] = _json_float(value)
        elif f.type == 'int':
            out[f.name] = int(value)
        else:
            out[f.name] = str(value)
    return out


def _number(name: str, value: object, kind: type[float]) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ConfigError(f'excitation parameter {name!r} = {value!r} is not a number')
    try:
        number = float(value)
    except ValueError:
        raise ConfigError(f'excitation parameter {name!r} = {value!r} is not a number') from None
    if kind is int:
        if number != int(number):
            raise ConfigError(f'excitation parameter {name!r} = {value!r} is not an integer')
        return int(number)
    return number


def spec_from_dict(data: object) -> ExcitationSpec:
    """
    The spec of :func:`spec_to_dict`'s data; missing keys take the defaults.

    Raises
    ------
    ConfigError
        For an unknown key or a value of the wrong type (named). Values are not checked
        against a sample time: :func:`check_spec` does that.
    """
    if not isinstance(data, dict):
        raise ConfigError(f'excitation parameters must be a mapping, got {data!r}')
    known = {f.name: f for f in fields(ExcitationSpec)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(f'unknown excitation parameter(s) {unknown}')
    values: dict[str, Any] = {}
    for name, value in data.items():
        if name in ('direction', 'frequencies'):
            if not isinstance(value, (list, tuple)):
                raise ConfigError(f'excitation parameter {name!r} = {value!r} is not a list')
            values[name] = [_number(name, v, float) for v in value]
        elif known[name].type == 'str':
            if not isinstance(value, str):
                raise ConfigError(f'excitation parameter {name!r} = {value!r} is not a string')
            values[name] = value
        else:
            values[name] = _number(name, value, int if known[name].type == 'int' else float)
    return ExcitationSpec(**values)


def spec_message(spec: ExcitationSpec, sample_rate: float, source: str) -> str:
    """JSON text the exciter publishes: format, source name, sample_rate [Hz], spec."""
    return json.dumps({'format': MESSAGE_FORMAT, 'source': source,
                       'sample_rate': float(sample_rate), 'excitation': spec_to_dict(spec)},
                      allow_nan=False, sort_keys=True)


def parse_spec_message(text: str) -> tuple[ExcitationSpec, float, str]:
    """Spec, sample time dt = 1 / sample_rate [s] and source name of :func:`spec_message`."""
    try:
        data = json.loads(text)
    except ValueError as err:
        raise ConfigError(f'excitation message is not JSON: {err}') from None
    if not isinstance(data, dict) or data.get('format') != MESSAGE_FORMAT:
        raise ConfigError(f'excitation message of an unknown format: {text[:200]!r}')
    try:
        rate = _number('sample_rate', data['sample_rate'], float)
        spec = spec_from_dict(data['excitation'])
        source = str(data['source'])
    except KeyError as err:
        raise ConfigError(f'excitation message lacks {err}') from None
    if not 0 < rate < math.inf:
        raise ConfigError(f'excitation message: sample_rate {rate!r} Hz is not > 0')
    return spec, sample_time(rate), source
