"""
How a JointState message is filled from a vector of values, ROS-free.

A :class:`TopicLayout` picks each joint's position, velocity and effort from a flat vector (the
plant's outputs y of one step, or of several steps flattened); :func:`batch_layout` repeats a
layout over the rows of a flattened array. Which output port goes to which topic, joint and
field is :data:`pentapod_sim.interface.PORT_LOCATION`; :func:`pentapod_sim.interface.state_layouts`
builds the layouts of the state topics from it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

#: The value fields of a JointState, in message order.
FIELDS = ('position', 'velocity', 'effort')


@dataclass
class TopicLayout:
    """
    How to fill one JointState message from a vector y.

    Attributes
    ----------
    topic : str
        Topic name.
    joints : list of str
        JointState names.
    position_index, velocity_index, effort_index : (n_joints,) ndarray of int
        Index into y, -1 where the joint lacks the quantity (published as NaN). A layout in which
        no joint has an effort publishes an empty effort array (JointState's "not given").
    """

    topic: str
    joints: list[str]
    position_index: npt.NDArray[np.intp]
    velocity_index: npt.NDArray[np.intp]
    effort_index: npt.NDArray[np.intp] | None = None
    _ext: npt.NDArray[np.float64] = field(default_factory=lambda: np.full(1, np.nan),
                                          repr=False, compare=False)
    _has_effort: bool = field(default=False, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.effort_index is None:
            self.effort_index = np.full(len(self.joints), -1, dtype=np.intp)
        # fixed with the layout, and values() asks every step
        self._has_effort = bool((self.effort_index >= 0).any())

    @property
    def has_effort(self) -> bool:
        """True if at least one joint takes an effort from y."""
        return self._has_effort

    def index(self, name: str) -> npt.NDArray[np.intp]:
        """The index array of a field (``'position'``, ``'velocity'`` or ``'effort'``)."""
        found = {'position': self.position_index, 'velocity': self.velocity_index,
                 'effort': self.effort_index}[name]
        assert found is not None
        return found

    def values(self, y: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64],
                                                          npt.NDArray[np.float64],
                                                          npt.NDArray[np.float64]]:
        """
        Positions, velocities and efforts of the joints from y.

        NaN where a joint lacks the quantity; an empty effort array if no joint has one.
        """
        if self._ext.size != y.size + 1:        # y and a NaN, which index -1 picks
            self._ext = np.full(y.size + 1, np.nan)
        self._ext[:-1] = y     # once per step: reused (np.append cost 6 % of a composed step)
        effort = (self._ext[self.effort_index] if self._has_effort else self._ext[:0])
        return self._ext[self.position_index], self._ext[self.velocity_index], effort


def batch_layout(layout: TopicLayout, row_length: int, rows: int, topic: str) -> TopicLayout:
    """
    Layout of ``rows`` samples of ``layout`` in one message, on the flattened (rows, n) array.

    Sample j (row j of an array whose rows have ``row_length`` values) becomes the joints
    ``<joint>@<j>``, in the order of ``layout``'s joints, sample after sample.
    """
    offsets = np.arange(rows)[:, None] * row_length

    def flat(index: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
        return np.where(index < 0, -1, offsets + index).reshape(-1)
    return TopicLayout(topic, [f'{j}@{s}' for s in range(rows) for j in layout.joints],
                       flat(layout.index('position')), flat(layout.index('velocity')),
                       flat(layout.index('effort')))


def split_batch_name(name: str) -> tuple[str, int]:
    """``('tcp_x', 3)`` for the batched joint name ``'tcp_x@3'`` (ValueError if not one)."""
    joint, at, sample = name.rpartition('@')
    if not at or not joint or not sample.isdigit():
        raise ValueError(f'{name!r} is no batched joint name <joint>@<sample>')
    return joint, int(sample)
