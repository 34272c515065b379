"""
Which modes a check model holds: every FE mode below ``max(f_min, 2 sample_rate)``.

Kept apart from :mod:`pentapod_sim.plant.check_model`, which builds check models from the FE
model: the plant node's parameter table takes its default from here, and the force-source
nodes, which import that table, must not load the FE code (test/test_layout.py).
"""
from __future__ import annotations

import numpy as np

from pentapod_sim.errors import ConfigError

#: Default lowest cut-off of the check model's modes [Hz].
DEFAULT_CHECK_F_MIN = 5000.0
#: Highest cut-off of a check model [Hz]: sample rates up to 12.5 kHz with the 2 x rule.
MAX_CHECK_F_MAX = 25000.0
#: What a check model's cut-off is made of (named in the errors).
RULE = 'max(check f_min, 2 x sample_rate)'


def check_f_max(sample_rate: float, f_min: float = DEFAULT_CHECK_F_MIN) -> float:
    """
    Cut-off of the check model's modes [Hz]: ``max(f_min, 2 * sample_rate)``.

    Parameters
    ----------
    sample_rate : float
        Sample rate of the loop [Hz], > 0.
    f_min : float
        Lowest cut-off [Hz], > 0 (default 5 kHz).
    """
    for name, value in (('sample_rate', sample_rate), ('check model f_min', f_min)):
        if not np.isfinite(value) or value <= 0:
            raise ConfigError(f'{name} must be > 0 Hz, got {value!r}')
    f_max = float(max(f_min, 2.0 * sample_rate))
    if f_max > MAX_CHECK_F_MAX:
        which = (f'sample_rate = {sample_rate:g} Hz' if 2.0 * sample_rate >= f_min
                 else f'check f_min = {f_min:g} Hz')
        raise ConfigError(f'truncation check: {which} asks for the FE modes below {f_max:g} Hz '
                          f'({RULE}), above the bound of {MAX_CHECK_F_MAX:g} Hz '
                          '(docs/statespace.md); lower it, or switch the check off (plant '
                          'parameter loop_check: off)')
    return f_max
