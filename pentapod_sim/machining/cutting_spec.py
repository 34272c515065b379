"""
The record of a cutting run's operation: what a cutting node publishes once, what analysis reads.

A cutting node publishes its operation once per run on
:data:`pentapod_sim.interface.CUTTING_SPEC` (std_msgs/String, transient local, so a recorder
started later still records it): the JSON text of :func:`spec_message`. It holds everything the
analysis of the recording needs and the node's parameters do not say by themselves once the
machining table is edited: spindle speed [rpm], teeth, axial depth [m], feed per tooth [m],
entry, exit and feed angles [rad], the cutting coefficients K_tc [N/m^2], K_rc / K_tc [-],
K_te and K_re [N/m], the plant sample rate [Hz], the operation's name and the source's name.
:func:`parse_spec_message` returns the same :class:`CuttingConditions` bit for bit (JSON keeps
a float's shortest repr).
"""
from __future__ import annotations

from dataclasses import dataclass
import json
import math
from typing import Any

from pentapod_sim.errors import ConfigError
from pentapod_sim.machining.cutting_process import CuttingConditions
from pentapod_sim.machining.milling_cut import MillingCut

#: Keys of the JSON record, in this order.
SPEC_KEYS = ('source', 'operation', 'sample_rate', 'spindle_speed', 'teeth', 'axial_depth',
             'feed_per_tooth', 'entry_angle', 'exit_angle', 'feed_angle',
             'tangential_coefficient', 'radial_ratio', 'edge_tangential', 'edge_radial')


@dataclass(frozen=True)
class CuttingSpec:
    """A cutting run's operation: conditions, plant sample rate [Hz], operation, source."""

    conditions: CuttingConditions
    sample_rate: float
    operation: str = ''
    source: str = ''

    @property
    def dt(self) -> float:
        """Plant sample time [s]."""
        return 1.0 / self.sample_rate


def spec_message(spec: CuttingSpec) -> str:
    """The JSON text of a cutting run's record (module docstring)."""
    cond, cut = spec.conditions, spec.conditions.cut
    values: dict[str, Any] = {
        'source': spec.source, 'operation': spec.operation, 'sample_rate': spec.sample_rate,
        'spindle_speed': cond.spindle_speed, 'teeth': cut.teeth,
        'axial_depth': cond.axial_depth, 'feed_per_tooth': cond.feed_per_tooth,
        'entry_angle': cut.entry_angle, 'exit_angle': cut.exit_angle,
        'feed_angle': cut.feed_angle, 'tangential_coefficient': cut.tangential_coefficient,
        'radial_ratio': cut.radial_ratio, 'edge_tangential': cond.edge_tangential,
        'edge_radial': cond.edge_radial}
    return json.dumps({k: values[k] for k in SPEC_KEYS})


def parse_spec_message(text: str) -> CuttingSpec:
    """
    The record back from its JSON text.

    Raises
    ------
    ConfigError
        If the text is not such a record or a value is out of range (naming it).
    """
    try:
        doc = json.loads(text)
    except ValueError as err:
        raise ConfigError(f'not a cutting record: {err}') from None
    if not isinstance(doc, dict):
        raise ConfigError('not a cutting record: not a JSON object')
    missing = [k for k in SPEC_KEYS if k not in doc]
    if missing:
        raise ConfigError(f'cutting record lacks {", ".join(missing)}')
    try:
        numbers = {k: float(doc[k]) for k in SPEC_KEYS[2:] if k != 'teeth'}
        teeth = doc['teeth']
        if isinstance(teeth, bool) or not isinstance(teeth, int):
            raise ConfigError(f'teeth = {teeth!r} is not an integer')
    except (TypeError, ValueError) as err:
        raise ConfigError(f'cutting record: {err}') from None
    rate = numbers['sample_rate']
    if not (math.isfinite(rate) and rate > 0):
        raise ConfigError(f'cutting record: sample_rate = {rate!r} Hz must be > 0')
    cut = MillingCut(teeth, numbers['tangential_coefficient'], numbers['radial_ratio'],
                     numbers['entry_angle'], numbers['exit_angle'], numbers['feed_angle'])
    conditions = CuttingConditions(cut, numbers['spindle_speed'], numbers['axial_depth'],
                                   numbers['feed_per_tooth'], numbers['edge_tangential'],
                                   numbers['edge_radial'])
    return CuttingSpec(conditions, rate, str(doc['operation']), str(doc['source']))
