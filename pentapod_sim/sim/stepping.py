"""
Discrete stepping core of the plant: lockstep semantics, force sources, instability checks.

Convention (docs/architecture.md): at step k, t_k = k dt, the plant reports
``y_k = C x_k + D u_{k-1}``; every force source answers ``u_k`` for that step; then
``x_{k+1} = A_d x_k + B_d u_k`` (exact zero-order hold, A_d/B_d from
:meth:`pentapod_sim.plant.model.PlantModel.discretize`). The ROS plant node, the offline
closed-loop simulator (:mod:`pentapod_sim.sim.closed_loop`) and the benchmarks all use this class,
so a lockstep ROS run reproduces the offline run to rounding.

Units: SI, as the model's ports (inputs N or N m, outputs m, m/s, rad, rad/s).
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
import logging
import math
import sys
from typing import Mapping, Sequence

import control
import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import ConfigError, PortError, RunError
from pentapod_sim.sim.modal_blocks import modal_blocks

LOG = logging.getLogger(__name__)

#: Default bound on the Euclidean state norm; a modal state of 1e3 means metres of motion.
DEFAULT_MAX_STATE_NORM = 1.0e3


class DiscretePlant:
    """
    Step a discrete state space with named ports by the lockstep convention.

    A modal plant (the layout of :meth:`pentapod_sim.plant.model.PlantModel.discrete_matrices`:
    states ``[q; dq]``, so A_d couples mode i only through the four diagonals of its m x m
    blocks) is advanced with its 2x2 ZOH blocks, ``x_i <- (P_i0 q + P_i1 dq) + (B_d u)_i``,
    elementwise on (2, m) arrays: four numpy calls per step (B_d u, the products, two sums)
    instead of a dense (2m x 2m) product. Any other A_d is stepped densely. The two paths
    round differently, but each is deterministic, so every user of this class (ROS node, offline
    loop) gets the same bits.

    Parameters
    ----------
    sys : control.StateSpace
        Discrete system (``sys.dt > 0``) with ``input_labels`` / ``output_labels`` = port names.
    max_state_norm : float, optional
        Bound on ``||w x||_2``; exceeding it (or a non-finite state) raises :class:`RunError`.
    state_scale : (n,) array_like, optional
        Weights ``w`` of the states in that norm (default 1: the modal coordinates as they
        are). A plant with the feed drives' rotors gives their states weights that make them
        mass-normalised coordinates like the modes'
        (:meth:`pentapod_sim.plant.drives.DrivenPlant.state_scale`), so one bound means the
        same for every kind of state.

    Attributes
    ----------
    dt : float
        Sample time [s].
    k : int
        Index of the current step (outputs of step k are available, u_k not yet applied).
    x : (n,) ndarray
        State x_k (assigning copies into the plant's buffer).
    u_prev : (n_in,) ndarray
        Input of the previous step u_{k-1} (feeds through D into y_k).
    modal : bool
        True if A_d has the modal 2x2-block layout and is stepped blockwise.
    """

    def __init__(self, sys: control.StateSpace, max_state_norm: float = DEFAULT_MAX_STATE_NORM,
                 state_scale: npt.ArrayLike | None = None):
        if not sys.isdtime(strict=True) or not np.isfinite(float(sys.dt)) or sys.dt <= 0:
            raise ConfigError(f'plant system must be discrete with dt > 0 s, got dt={sys.dt!r}')
        if not 0 < max_state_norm <= 1e150:     # its square must stay a finite float
            raise ConfigError(f'max_state_norm must lie in (0, 1e150], got {max_state_norm!r}')
        self.dt = float(sys.dt)
        # contiguous float64 copies (dense A_d is kept for the closed-loop matrices)
        self.a = np.ascontiguousarray(sys.A, dtype=float)
        self.b = np.ascontiguousarray(sys.B, dtype=float)
        self.c = np.ascontiguousarray(sys.C, dtype=float)
        self.d = np.ascontiguousarray(sys.D, dtype=float)
        self.input_names = list(sys.input_labels)
        self.output_names = list(sys.output_labels)
        self.input_index = {n: i for i, n in enumerate(self.input_names)}
        self.output_index = {n: i for i, n in enumerate(self.output_names)}
        self.has_feedthrough = bool(np.any(self.d))
        self.max_state_norm = float(max_state_norm)
        self._max_sq = self.max_state_norm ** 2
        self.state_scale: npt.NDArray[np.float64] | None = None
        if state_scale is not None:
            scale = np.asarray(state_scale, dtype=float)
            if scale.shape != (self.a.shape[0],) or not np.all(np.isfinite(scale) & (scale > 0)):
                raise ConfigError(f'state_scale must hold {self.a.shape[0]} finite weights > 0')
            if not np.all(scale == 1.0):
                self.state_scale = scale
        blocks = modal_blocks(self.a)
        self.modal = blocks is not None
        n, m = self.n_states, self.n_states // 2
        self._x = np.zeros(n)
        if blocks is not None:
            # work[j, i] = P_ij x_j (j = 0: q, 1: dq), work[2] = B_d u as (2, m);
            # x_i = (work[0, i] + work[1, i]) + work[2, i]
            self._blocks_t = np.ascontiguousarray(blocks.transpose(1, 0, 2))
            self._work = np.zeros((3, 2, m))
            self._products = self._work[:2]
            self._forced = self._work[2].reshape(n)
            self._x2 = self._x.reshape(2, m)
            self._x_j = self._x2[:, None, :]
            self._terms = tuple(self._work)
        self.reset()

    @property
    def n_states(self) -> int:
        """Number of states."""
        return self.a.shape[0]

    @property
    def time(self) -> float:
        """Time of the current step t_k = k dt [s]."""
        return self.k * self.dt

    @property
    def x(self) -> npt.NDArray[np.float64]:
        """State x_k (a view of the plant's buffer: copy it to keep it)."""
        return self._x

    @x.setter
    def x(self, value: npt.ArrayLike) -> None:
        value = np.asarray(value, dtype=float)
        if value.shape != self._x.shape:
            raise ConfigError(f'x0 has shape {value.shape}, expected ({self.n_states},)')
        self._x[:] = value

    def reset(self, x0: npt.ArrayLike | None = None,
              u_prev: npt.ArrayLike | None = None) -> None:
        """Set step 0 with state ``x0`` and input u_{-1} ``u_prev`` (defaults zero)."""
        self.k = 0
        self.x = np.zeros(self.n_states) if x0 is None else x0
        n_in = len(self.input_names)
        self.u_prev = np.zeros(n_in) if u_prev is None else np.array(u_prev, dtype=float)
        if self.u_prev.shape != (n_in,):
            raise ConfigError(f'u_prev has shape {self.u_prev.shape}, expected ({n_in},)')

    def outputs(self, out: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.float64]:
        """
        Return y_k = C x_k + D u_{k-1} (units of the output ports).

        Parameters
        ----------
        out : (n_out,) ndarray, optional
            C-contiguous float64 array to write y_k into (same numbers as without).
        """
        y = np.dot(self.c, self._x, out=out)
        if self.has_feedthrough:
            y += self.d @ self.u_prev
        return y

    def advance(self, u: npt.NDArray[np.float64]) -> None:
        """
        Apply u_k (input port units) and move to step k+1: x_{k+1} = A_d x_k + B_d u_k.

        Raises
        ------
        RunError
            If the new state is non-finite or its norm exceeds ``max_state_norm``.
        """
        u = np.array(u, dtype=float)
        x = self._x
        if self.modal:
            x2, (q_terms, dq_terms, forced) = self._x2, self._terms
            np.dot(self.b, u, out=self._forced)
            np.multiply(self._blocks_t, self._x_j, out=self._products)
            np.add(q_terms, dq_terms, out=x2)
            np.add(x2, forced, out=x2)
        else:
            new = self.a @ x
            new += self.b @ u
            x[:] = new
        self.u_prev = u
        self.k += 1
        w = x if self.state_scale is None else x * self.state_scale
        if not np.dot(w, w) <= self._max_sq:  # also catches NaN
            norm = float(np.sqrt(w @ w))
            weighted = '' if self.state_scale is None else ' (weighted: state_scale)'
            raise RunError(f'plant unstable at step {self.k} (t = {self.time:.6g} s): state '
                           f'norm{weighted} {norm:.3g} exceeds max_state_norm '
                           f'{self.max_state_norm:.3g}; a feedback gain is probably too high')

    def state_norm(self) -> float:
        """The norm the divergence guard bounds, ``||w x_k||_2``."""
        w = self._x if self.state_scale is None else self._x * self.state_scale
        return float(np.sqrt(w @ w))


@dataclass
class ForceSource:
    """
    A named force source and the input ports it may drive.

    Attributes
    ----------
    name : str
        Source name (topic /pentapod/forces/<name>).
    ports : tuple of str
        Input ports it may drive (empty = every input port of the plant).
    """

    name: str
    ports: tuple[str, ...] = ()


class ForceMixer:
    """
    Collect per-step force messages from several sources, validate them and sum them.

    A message carries port names, efforts [N or N m] and the step it answers. Bad messages
    (unknown source, unknown or forbidden port, not exactly the source's ports, wrong length,
    NaN/Inf, above max_effort, stale or future step) are rejected and counted per (source,
    reason); nothing already accepted is lost. A source's ports are its configured ones
    (``ForceSource.ports``) or, if none are configured, those of its first accepted answer:
    every answer must carry exactly these, once each, in any order (an empty answer, a subset
    or a repeated name is rejected), so no answer can displace another with fewer forces.

    Parameters
    ----------
    input_names : sequence of str
        The plant's input ports (order of the summed vector).
    sources : sequence of ForceSource
        Sources expected to answer every step in lockstep.
    max_effort : float, optional
        Largest accepted |effort| per port [N or N m]; larger ones are rejected ('limit').
    """

    def __init__(self, input_names: Sequence[str], sources: Sequence[ForceSource],
                 max_effort: float = math.inf):
        self.input_names = list(input_names)
        self.max_effort = float(max_effort)
        self._index = {n: i for i, n in enumerate(self.input_names)}
        self.sources: dict[str, ForceSource] = {}
        for src in sources:
            if src.name in self.sources:
                raise ConfigError(f'force source {src.name!r} is configured twice')
            for port in src.ports:
                if port not in self._index:
                    raise PortError(f'force source {src.name!r}: port {port!r} is not an input '
                                    'of the plant; inputs: ' + ', '.join(self.input_names))
            self.sources[src.name] = src
        self._allowed = {s.name: (set(s.ports) or set(self.input_names))
                         for s in self.sources.values()}
        # the ports every answer of a source must carry: configured, else its first answer's
        self.ports: dict[str, frozenset[str]] = {s.name: frozenset(s.ports)
                                                 for s in self.sources.values() if s.ports}
        self._cache: dict[tuple[str, tuple[str, ...]], npt.NDArray[np.intp]] = {}
        self.rejected: Counter[tuple[str, str]] = Counter()     # (source, reason)
        self.accepted: Counter[str] = Counter()
        n = len(self.input_names)
        self.latest = {name: np.zeros(n) for name in self.sources}
        self.latest_step = dict.fromkeys(self.sources, -1)
        self.latest_names: dict[str, Sequence[str]] = dict.fromkeys(self.sources, ())
        #: source -> (step, reason) of its last rejected message
        self.last_rejected: dict[str, tuple[int, str]] = {}

    def _indices(self, source: str, names: tuple[str, ...]) -> npt.NDArray[np.intp] | str:
        """Map port names to input indices (cached per name tuple) or return a reject reason."""
        key = (source, names)
        idx = self._cache.get(key)
        if idx is not None:
            return idx
        allowed = self._allowed[source]
        for name in names:
            if name not in self._index:
                return f'unknown_port: {name!r} is not an input port of the plant'
            if name not in allowed:
                return f'forbidden_port: {name!r} is not among the ports of this source'
        if len(set(names)) != len(names):
            return f'duplicate_port: names {list(names)} repeat a port'
        own = self.ports.get(source)
        if not names or (own is not None and set(names) != own):
            lacks = sorted(own - set(names)) if own is not None else []
            extra = sorted(set(names) - own) if own is not None else []
            return ('ports: ' + ('an empty answer' if not names else
                                 f'lacks {lacks}' if lacks else f'adds {extra}')
                    + f' (the source drives {sorted(own) if own else "some ports"})')
        idx = np.array([self._index[n] for n in names], dtype=np.intp)
        self._cache[key] = idx
        return idx

    def submit(self, source: str, names: Sequence[str], efforts: npt.ArrayLike, step: int,
               current_step: int, exact: bool = True) -> str | None:
        """
        Offer one force message; return None if accepted, else the reason it was rejected.

        Parameters
        ----------
        source : str
            Source name.
        names : sequence of str
            Input port names of the efforts.
        efforts : array_like
            Forces [N] / moments [N m], one per name.
        step : int
            Step the message answers (from its stamp).
        current_step : int
            Step the plant is waiting for.
        exact : bool
            Lockstep (True): only ``step == current_step`` is accepted; real time (False):
            any step <= current_step that is newer than the held one.
        """
        values = np.asarray(efforts, dtype=float)
        reason = self._check(source, names, values, step, current_step, exact)
        if reason is not None:
            self.rejected[(source, reason.split(':')[0])] += 1
            self.last_rejected[source] = (step, reason)
            return reason
        if source not in self.ports:        # its first accepted answer fixes its ports
            self.ports[source] = frozenset(names)
            self._cache = {key: idx for key, idx in self._cache.items() if key[0] != source
                           or set(key[1]) == self.ports[source]}
        vec = self.latest[source]
        vec[:] = 0.0
        vec[self._cache[(source, tuple(names))]] = values
        self.latest_step[source] = step
        self.latest_names[source] = names      # the ports of latest[source], message order
        self.accepted[source] += 1
        return None

    def _check(self, source: str, names: Sequence[str], values: npt.NDArray[np.float64],
               step: int, current_step: int, exact: bool) -> str | None:
        """Return the reason a message (efforts as a float array) is unacceptable, or None."""
        if source not in self.sources:
            return f'unknown_source: {source!r} is not a configured force source'
        if len(names) != len(values):
            return f'length: {len(names)} names but {len(values)} efforts'
        idx = self._indices(source, tuple(names))
        if isinstance(idx, str):
            return idx
        # one vectorised test for the usual case (NaN and, with the bound finite, Inf fail it
        # too); the reasons after it
        bound = min(self.max_effort, sys.float_info.max)
        if not (np.abs(values) <= bound).all():
            if not np.all(np.isfinite(values)):
                return f'nonfinite: effort {list(values)}'
            worst = int(np.argmax(np.abs(values)))
            return (f'limit: effort {values[worst]:.6g} on {names[worst]!r} exceeds max_effort '
                    f'{self.max_effort:.6g}')
        if step > current_step:
            return f'future: step {step} (plant at step {current_step})'
        if step < current_step if exact else step <= self.latest_step[source]:
            return f'stale: step {step} (plant at step {current_step})'
        if exact and self.latest_step[source] == step:
            return f'duplicate: second answer for step {step}'
        return None

    def rejected_at(self, step: int, sources: Sequence[str]) -> dict[str, str]:
        """Of ``sources``, those whose last rejected message answered ``step``: source -> why."""
        return {s: self.last_rejected[s][1] for s in sources
                if self.last_rejected.get(s, (None,))[0] == step}

    def drop(self, source: str) -> None:
        """Set the held force of ``source`` to zero (a source that left)."""
        self.latest[source][:] = 0.0

    def missing(self, step: int) -> list[str]:
        """Sources that have not answered ``step`` yet."""
        return [n for n, s in self.latest_step.items() if s < step]

    def total(self) -> npt.NDArray[np.float64]:
        """Sum of the held forces of all sources (input vector u)."""
        u = np.zeros(len(self.input_names))
        for vec in self.latest.values():
            u += vec
        return u

    def reject_summary(self) -> str:
        """One line listing rejected messages per source and reason."""
        if not self.rejected:
            return 'no rejected messages'
        return ', '.join(f'{s}/{r}: {c}' for (s, r), c in sorted(self.rejected.items()))


def parse_sources(names: Sequence[str], ports: Mapping[str, Sequence[str]]) -> list[ForceSource]:
    """Build :class:`ForceSource` objects from names and a name -> ports mapping."""
    return [ForceSource(n, tuple(ports.get(n, ()))) for n in names]
