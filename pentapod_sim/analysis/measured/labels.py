"""
Labels of measured DOFs: ``POINT:COMP``, ``NODE:COMP`` or a port name, and UFF directions.

``COMP`` is ``x``, ``y``, ``z``, ``rx``, ``ry``, ``rz`` (also ``ux``.. and ``1``..``6``) with an
optional sign: ``tcp:-y`` is the TCP displacement along -y. UFF directions are 1..6 for +X..+RZ
and negative for the opposite sense.
"""
from __future__ import annotations

from dataclasses import dataclass

from pentapod_sim.errors import ConfigError

COMPONENTS = ('x', 'y', 'z', 'rx', 'ry', 'rz')


@dataclass(frozen=True)
class DofLabel:
    """A measured DOF: a point, node or port, and for points and nodes a signed component."""

    target: str
    component: int | None = None     # 0..5, None for a port
    sign: float = 1.0

    @property
    def is_port(self) -> bool:
        """True for a port name (no component)."""
        return self.component is None

    def __str__(self) -> str:
        if self.component is None:
            return self.target
        return f'{self.target}:{"-" if self.sign < 0 else "+"}{COMPONENTS[self.component]}'


def parse_component(text: str, where: str = 'DOF label') -> tuple[int, float]:
    """(component 0..5, sign) of ``x``, ``-ry``, ``+uz``, ``2``, ``-6``, ..."""
    raw = text.strip().lower()
    sign = -1.0 if raw.startswith('-') else 1.0
    body = raw.lstrip('+-')
    if body.startswith('u'):
        body = body[1:]
    if body.isdigit() and 1 <= int(body) <= 6:
        return int(body) - 1, sign
    if body in COMPONENTS:
        return COMPONENTS.index(body), sign
    raise ConfigError(f'{where}: component {text!r} is not one of x, y, z, rx, ry, rz '
                      '(optionally signed, or 1..6)')


def parse_label(text: str) -> DofLabel:
    """A :class:`DofLabel` from ``POINT:COMP``, ``NODE:COMP`` or a port name."""
    text = str(text).strip()
    if ':' not in text:
        if not text:
            raise ConfigError('empty DOF label')
        return DofLabel(text)
    target, _, comp = text.rpartition(':')
    if not target:
        raise ConfigError(f'DOF label {text!r}: no point or node before the colon')
    component, sign = parse_component(comp, f'DOF label {text!r}')
    return DofLabel(target.strip(), component, sign)


def uff_label(node: int, direction: int, names: dict[int, str]) -> DofLabel:
    """The label of a UFF (node, direction): ``names[node]`` or the node number itself."""
    if not 1 <= abs(int(direction)) <= 6:
        raise ConfigError(f'UFF node {node}: direction {direction} is not +-1..6')
    target = names.get(int(node), str(int(node)))
    return DofLabel(target, abs(int(direction)) - 1, -1.0 if direction < 0 else 1.0)
