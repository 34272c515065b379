"""
The ROS contract of the testbed, ROS-free: topic names, message types, QoS, state-topic layouts.

This module is the one home of these facts; the nodes build their rclpy QoS profiles from
:data:`QOS` (:func:`pentapod_sim.nodes.common.qos`), the recorder and the analysis read the topic
names and types from here. The plant node publishes its outputs as sensor_msgs/JointState
messages (docs/architecture.md, docs/nodes.md):

* ``/pentapod/tcp_state``: joints ``tcp_{x,y,z}``, position = ``tcp_displacement_*`` [m],
  velocity = ``tcp_velocity_*`` [m/s];
* ``/pentapod/strut_states``: ``strut{i}_bending_{2,3}`` (position [rad] = bending, velocity
  [rad/s] = bending rate) and ``strut{i}_axial`` (position [m], velocity [m/s]);
* ``/pentapod/pma_mount_state``: ``pma_mount_{x,y,z}``, velocity = ``pma_mount_velocity_*``
  [m/s] (position NaN: the plant has no displacement output there).

A quantity the model lacks is published as NaN.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import PortError
from pentapod_sim.plant.ports import AXES, N_STRUTS

#: Namespace of every testbed topic except /clock.
NAMESPACE = '/pentapod/'
CLOCK = '/clock'
TCP_STATE = '/pentapod/tcp_state'
STRUT_STATES = '/pentapod/strut_states'
PMA_MOUNT_STATE = '/pentapod/pma_mount_state'
STATE_TOPICS = (TCP_STATE, STRUT_STATES, PMA_MOUNT_STATE)
EXCITATION = '/pentapod/excitation'
PMA_STATE = '/pentapod/pma/state'
#: A force source ``<name>`` publishes on ``FORCE_PREFIX + <name>``.
FORCE_PREFIX = '/pentapod/forces/'
#: Channels only the live view serves (Foxglove WebSocket, not ROS topics): its derived data.
LIVE_PREFIX = '/pentapod/live/'
#: Run status (sensor_msgs/JointState, one joint per figure: pentapod_sim.live.status).
LIVE_STATUS = '/pentapod/live/status'
#: Running amplitude spectrum of the TCP response: ``TCP_SPECTRUM_PREFIX + 'frequency'`` [Hz]
#: and ``TCP_SPECTRUM_PREFIX + <joint>`` (tcp_x, ...) [m], std_msgs/Float64MultiArray each.
TCP_SPECTRUM_PREFIX = '/pentapod/live/tcp_spectrum/'

JOINT_STATE = 'sensor_msgs/msg/JointState'
WRENCH_STAMPED = 'geometry_msgs/msg/WrenchStamped'
CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'
FLOAT64_MULTI_ARRAY = 'std_msgs/msg/Float64MultiArray'
#: Message type of every fixed topic (force topics are JOINT_STATE).
TOPIC_TYPES = {CLOCK: CLOCK_TYPE, TCP_STATE: JOINT_STATE, STRUT_STATES: JOINT_STATE,
               PMA_MOUNT_STATE: JOINT_STATE, EXCITATION: WRENCH_STAMPED, PMA_STATE: JOINT_STATE}


def force_topic(source: str) -> str:
    """Topic of the force source ``source``."""
    return FORCE_PREFIX + source


def tcp_spectrum_topic(name: str) -> str:
    """Live-view channel of the TCP spectrum: ``'frequency'`` or a TCP joint name."""
    return TCP_SPECTRUM_PREFIX + name


def is_testbed_topic(topic: str) -> bool:
    """True for /clock and every topic under the testbed namespace."""
    return topic == CLOCK or topic.startswith(NAMESPACE)


@dataclass(frozen=True)
class QosSpec:
    """
    QoS of one class of topics, as plain data (every testbed topic is reliable and volatile).

    Attributes
    ----------
    depth : int
        KEEP_LAST history depth [messages]: how far a slow reader may fall behind before a
        reliable writer drops its oldest unacknowledged message.
    """

    depth: int
    reliability: str = 'reliable'
    durability: str = 'volatile'


#: History of the state and information streams: how far a slow reader (a recorder on a busy
#: machine) may fall behind, in steps.
STREAM_DEPTH = 10000
#: QoS per class of topic: plant outputs and /clock ('state'), forces from the sources
#: ('force'; one message per step), diagnostics such as PMA state and excitation ('info').
QOS = {'state': QosSpec(STREAM_DEPTH), 'force': QosSpec(100), 'info': QosSpec(STREAM_DEPTH)}


def _table() -> dict[str, tuple[str, str, str]]:
    """Map output port -> (topic, joint name, 'position' | 'velocity')."""
    table = {}
    for a in AXES:
        table[f'tcp_displacement_{a}'] = (TCP_STATE, f'tcp_{a}', 'position')
        table[f'tcp_velocity_{a}'] = (TCP_STATE, f'tcp_{a}', 'velocity')
        table[f'pma_mount_velocity_{a}'] = (PMA_MOUNT_STATE, f'pma_mount_{a}', 'velocity')
    for i in range(1, N_STRUTS + 1):
        for k in (2, 3):
            table[f'strut{i}_bending_{k}'] = (STRUT_STATES, f'strut{i}_bending_{k}', 'position')
            table[f'strut{i}_bending_rate_{k}'] = (STRUT_STATES, f'strut{i}_bending_{k}',
                                                   'velocity')
        table[f'strut{i}_axial_displacement'] = (STRUT_STATES, f'strut{i}_axial', 'position')
        table[f'strut{i}_axial_velocity'] = (STRUT_STATES, f'strut{i}_axial', 'velocity')
    return table


PORT_LOCATION = _table()


def port_location(port: str) -> tuple[str, str, str]:
    """Return (topic, joint, field) carrying an output port (PortError if none)."""
    try:
        return PORT_LOCATION[port]
    except KeyError:
        raise PortError(f'output port {port!r} is not published in any state topic') from None


@dataclass
class TopicLayout:
    """
    How to fill one state message from the output vector y.

    Attributes
    ----------
    topic : str
        Topic name.
    joints : list of str
        JointState names.
    position_index, velocity_index : (n_joints,) ndarray of int
        Index into y, -1 where the model lacks the quantity (published as NaN).
    """

    topic: str
    joints: list[str]
    position_index: npt.NDArray[np.intp]
    velocity_index: npt.NDArray[np.intp]

    def values(self, y: npt.NDArray[np.float64]) -> tuple[npt.NDArray, npt.NDArray]:
        """Positions and velocities of the joints from y (NaN where missing)."""
        ext = np.append(y, np.nan)  # index -1 picks the NaN
        return ext[self.position_index], ext[self.velocity_index]


def state_layouts(output_names: Sequence[str]) -> list[TopicLayout]:
    """Layouts of the state topics that carry at least one of the model's outputs."""
    index = {n: i for i, n in enumerate(output_names)}
    joints: dict[str, dict[str, dict[str, int]]] = {t: {} for t in STATE_TOPICS}
    for port in output_names:
        if port not in PORT_LOCATION:
            continue
        topic, joint, field = PORT_LOCATION[port]
        joints[topic].setdefault(joint, {})[field] = index[port]
    layouts = []
    for topic, table in joints.items():
        if not table:
            continue
        names = list(table)
        pos = np.array([table[j].get('position', -1) for j in names], dtype=np.intp)
        vel = np.array([table[j].get('velocity', -1) for j in names], dtype=np.intp)
        layouts.append(TopicLayout(topic, names, pos, vel))
    return layouts


def stamp_ns(step: int, dt: float) -> int:
    """Time stamp of step k [ns], t_k = k dt rounded to whole nanoseconds."""
    return int(round(step * dt * 1e9))


def step_of(stamp: int, dt: float) -> int:
    """Step index of a stamp [ns] (inverse of :func:`stamp_ns` for dt >= 1 ns)."""
    return int(round(stamp / (dt * 1e9)))
