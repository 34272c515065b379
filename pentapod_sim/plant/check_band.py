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
    return float(max(f_min, 2.0 * sample_rate))
