"""
A milling cut: the cutter's engaged angles, the linear cutting-force law, directional factors.

Conventions (those of Altintas & Budak 1995 and Insperger & Stepan 2004):

* The cutting frame has x_c along the feed and y_c normal to it. The immersion angle ``phi``
  of a tooth is measured from +y_c towards +x_c: the cutter turns clockwise seen from the side
  the tool axis points to (M03 seen from the spindle). The feed direction makes the angle
  ``feed_angle`` [rad] with the machine x axis in the machine x-y plane, so the cutting axes
  in machine coordinates are the columns of :meth:`MillingCut.rotation`.
* A tooth at ``phi`` cuts the chip ``h = f_t sin(phi) + (r(t) - r(t - T)) . n(phi)`` with
  ``n = (sin phi, cos phi)`` (:func:`chip_direction`) and ``r`` the tool's displacement
  relative to the workpiece; the force on the tool is ``F = K_t a h f(phi)`` with
  ``f = (-(cos phi + K_r sin phi), sin phi - K_r cos phi)`` (:func:`force_direction`): the
  tangential force ``K_t a h`` against the tooth's motion and the radial force ``K_r K_t a h``
  towards the cutter axis.
* Up-milling engages ``[0, arccos(1 - 2 a_e / D)]``, down-milling
  ``[arccos(2 a_e / D - 1), pi]`` (``a_e / D`` the radial immersion); a slot is ``[0, pi]``.

Units: angles [rad], K_t [N/m^2], K_r [-].
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError

#: The two ways a cutter can engage the workpiece.
MILLING_MODES = ('up', 'down')


def immersion_angles(radial_immersion: float, milling: str) -> tuple[float, float]:
    """
    Entry and exit angles [rad] of a straight cut.

    Parameters
    ----------
    radial_immersion : float
        Radial depth over cutter diameter ``a_e / D``, in (0, 1].
    milling : {'up', 'down'}
        Up-milling (chip thin to thick) or down-milling (climb, thick to thin).
    """
    if not 0.0 < radial_immersion <= 1.0:
        raise ConfigError(f'radial immersion a_e/D = {radial_immersion!r} must lie in (0, 1]')
    if milling not in MILLING_MODES:
        raise ConfigError(f'milling = {milling!r} must be one of {", ".join(MILLING_MODES)}')
    swept = math.acos(1.0 - 2.0 * radial_immersion)
    return (0.0, swept) if milling == 'up' else (math.pi - swept, math.pi)


@dataclass(frozen=True)
class MillingCut:
    """
    Engagement and linear cutting-force law of a milling operation (helix ignored).

    Attributes
    ----------
    teeth : int
        Number of teeth N (evenly spaced).
    tangential_coefficient : float
        Cutting coefficient K_t [N/m^2]: tangential force per unit chip area.
    radial_ratio : float
        K_r = K_rc / K_tc [-]: radial over tangential cutting coefficient.
    entry_angle, exit_angle : float
        Engaged immersion angles phi_st < phi_ex in [0, pi] [rad].
    feed_angle : float
        Angle of the feed direction from machine x in the machine x-y plane [rad].
    """

    teeth: int
    tangential_coefficient: float
    radial_ratio: float
    entry_angle: float
    exit_angle: float
    feed_angle: float = 0.0

    def __post_init__(self) -> None:
        if isinstance(self.teeth, bool) or not isinstance(self.teeth, int) or self.teeth < 1:
            raise ConfigError(f'teeth = {self.teeth!r} must be an integer >= 1')
        if not (math.isfinite(self.tangential_coefficient) and self.tangential_coefficient > 0):
            raise ConfigError(f'tangential coefficient K_t = {self.tangential_coefficient!r} '
                              'N/m^2 must be > 0')
        if not (math.isfinite(self.radial_ratio) and self.radial_ratio >= 0):
            raise ConfigError(f'radial ratio K_r = {self.radial_ratio!r} must be >= 0')
        if not 0.0 <= self.entry_angle < self.exit_angle <= math.pi:
            raise ConfigError(f'engagement [{self.entry_angle!r}, {self.exit_angle!r}] rad must '
                              'satisfy 0 <= entry < exit <= pi')
        if not math.isfinite(self.feed_angle):
            raise ConfigError(f'feed angle {self.feed_angle!r} rad is not finite')

    @classmethod
    def from_immersion(cls, teeth: int, tangential_coefficient: float, radial_ratio: float,
                       radial_immersion: float, milling: str,
                       feed_angle: float = 0.0) -> 'MillingCut':
        """A straight cut of radial immersion ``a_e / D``, up- or down-milling."""
        entry, exit_ = immersion_angles(radial_immersion, milling)
        return cls(teeth, tangential_coefficient, radial_ratio, entry, exit_, feed_angle)

    @property
    def tooth_angle(self) -> float:
        """Angle between neighbouring teeth 2 pi / N [rad]."""
        return 2.0 * math.pi / self.teeth

    def rotation(self) -> npt.NDArray[np.float64]:
        """(2, 2) matrix whose columns are the cutting axes x_c, y_c in machine x-y."""
        c, s = math.cos(self.feed_angle), math.sin(self.feed_angle)
        return np.array([[c, -s], [s, c]])

    def engaged(self, phi: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """True where an immersion angle (any real number, taken mod 2 pi) is engaged."""
        wrapped = np.mod(np.asarray(phi, dtype=float), 2.0 * math.pi)
        return (wrapped >= self.entry_angle) & (wrapped <= self.exit_angle)


def chip_direction(phi: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Unit vector n(phi) = (sin phi, cos phi) of the chip thickness, shape (..., 2)."""
    phi = np.asarray(phi, dtype=float)
    return np.stack([np.sin(phi), np.cos(phi)], axis=-1)


def force_direction(phi: npt.ArrayLike, radial_ratio: float) -> npt.NDArray[np.float64]:
    """Force on the tool per unit ``K_t a h``: (-(cos + K_r sin), sin - K_r cos), (..., 2)."""
    phi = np.asarray(phi, dtype=float)
    s, c = np.sin(phi), np.cos(phi)
    return np.stack([-(c + radial_ratio * s), s - radial_ratio * c], axis=-1)


def _antiderivative(phi: npt.NDArray[np.float64], kr: float) -> npt.NDArray[np.float64]:
    """J(phi) with dJ/dphi = f(phi) n(phi)^T (per unit K_t), shape (..., 2, 2)."""
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    return 0.25 * np.stack([np.stack([c2 - 2 * kr * phi + kr * s2,
                                      -s2 - 2 * phi + kr * c2], axis=-1),
                            np.stack([-s2 + 2 * phi + kr * c2,
                                      -c2 - 2 * kr * phi - kr * s2], axis=-1)], axis=-2)


def directional_factors(cut: MillingCut) -> npt.NDArray[np.float64]:
    """
    Altintas' directional factors [alpha] (2, 2), dimensionless, in the cutting frame.

    ``alpha_xx = 1/2 [cos 2phi - 2 K_r phi + K_r sin 2phi]`` between entry and exit, and so on
    (module docstring); the force averaged over a tooth period is
    ``F = N a K_t / (4 pi) [alpha] (r(t) - r(t - T))``.
    """
    ends = _antiderivative(np.array([cut.entry_angle, cut.exit_angle]), cut.radial_ratio)
    return 2.0 * (ends[1] - ends[0])


def engaged_integral(cut: MillingCut, phi_start: npt.ArrayLike,
                     phi_end: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    Integral of ``f(phi) n(phi)^T`` (per unit K_t) over the engaged part of [start, end].

    Parameters
    ----------
    cut : MillingCut
        Engagement and K_r.
    phi_start, phi_end : array_like
        Angle intervals [rad], ``0 <= end - start <= 2 pi``, any offset (taken mod 2 pi).

    Returns
    -------
    (..., 2, 2) ndarray
        The integral [rad]; divided by the interval's length it is the mean specific force
        matrix of one tooth.
    """
    start = np.asarray(phi_start, dtype=float)
    length = np.asarray(phi_end, dtype=float) - start
    if np.any(length < 0) or np.any(length > 2 * math.pi + 1e-12):
        raise ConfigError('angle intervals must have 0 <= length <= 2 pi')
    lo = np.mod(start, 2 * math.pi)
    hi = lo + length
    total = np.zeros(lo.shape + (2, 2))
    # the interval itself and, if it passes 2 pi, its part wrapped to [0, hi - 2 pi]
    for a, b in ((lo, np.minimum(hi, 2 * math.pi)), (np.zeros_like(lo), hi - 2 * math.pi)):
        a_in, b_in = np.maximum(a, cut.entry_angle), np.minimum(b, cut.exit_angle)
        part = _antiderivative(b_in, cut.radial_ratio) - _antiderivative(a_in,
                                                                         cut.radial_ratio)
        total += np.where((b_in > a_in)[..., None, None], part, 0.0)
    return total
