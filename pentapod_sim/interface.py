"""
The ROS contract of the testbed, ROS-free: topic names, message types, QoS, state-topic layouts.

This module is the one home of these facts; the nodes build their rclpy QoS profiles from
:data:`QOS` (:func:`pentapod_sim.nodes.common.qos`), the recorder and the analysis read the topic
names and types from here. The plant node publishes its outputs as sensor_msgs/JointState
messages (docs/architecture.md, docs/nodes.md):

* ``/pentapod/tcp_state``: joints ``tcp_{x,y,z}``, position = ``tcp_displacement_*`` [m],
  velocity = ``tcp_velocity_*`` [m/s];
* ``/pentapod/strut_states``: ``strut{i}_bending_{2,3}`` (position [rad] = bending, velocity
  [rad/s] = bending rate), ``strut{i}_axial`` (BP cardan joint: position [m], velocity [m/s]),
  ``strut{i}_chord_{2,3}`` (position [m] = chord displacement, velocity [m/s]) and
  ``strut{i}_drive`` (feed-drive link, strut against gimbal: position [m] =
  ``strut{i}_drive_displacement``, velocity [m/s], effort [N] = ``strut{i}_force``, the load
  cell between nut and gimbal); effort NaN for every other joint of the topic;
* ``/pentapod/pma_mount_state``: ``pma_mount_{x,y,z}``, velocity = ``pma_mount_velocity_*``
  [m/s] (position NaN: the plant has no displacement output there);
* ``/pentapod/tcp_state_fullrate`` (multi-rate plant, N = ``substeps`` > 1, published only while
  subscribed): the N full-rate TCP samples of exchange k in one message, stamp t_k, joints
  ``tcp_{x,y,z}@j`` (j = 0..N-1, sample time t_k + j dt / N), position [m], velocity [m/s]
  (:func:`fullrate_layout`).
* ``/pentapod/live/batch/<topic>`` (:func:`display_batch_topic`; published only while
  subscribed, by the live view): the *display batches* of the state topics and of every force
  source's topic, M steps (the plant's ``display_batch_period``) in one JointState, stamp of
  the first step, joints ``<joint>@j`` for step j of the batch (:func:`batch_layout`), the
  fields of the per-step topic, header.frame_id the step dt [s] as ``repr(dt)``.
* ``/pentapod/cutting/state`` (the cutting-process node, one message per step, stamp t_k):
  joints ``tooth_{j}`` (j = 1..N, :func:`cutting_joints`), position = immersion angle phi_j
  [rad, 0..2 pi], velocity = chip thickness h_j [m] (<= 0: the tooth cuts no chip), effort =
  tangential force F_t of the tooth [N] (0 out of the cut). A tooth cuts when its angle lies
  between the entry and exit angles of :data:`CUTTING_SPEC` and h_j > 0. The force on the TCP
  is the node's answer on its force topic.

A quantity the model lacks is published as NaN; a topic on which no joint has an effort
publishes an empty effort array.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.errors import PortError
from pentapod_sim.plant.ports import AXES, N_STRUTS
from pentapod_sim.topic_layout import batch_layout, TopicLayout

#: Namespace of every testbed topic except /clock.
NAMESPACE = '/pentapod/'
CLOCK = '/clock'
TCP_STATE = '/pentapod/tcp_state'
STRUT_STATES = '/pentapod/strut_states'
PMA_MOUNT_STATE = '/pentapod/pma_mount_state'
STATE_TOPICS = (TCP_STATE, STRUT_STATES, PMA_MOUNT_STATE)
TCP_STATE_FULLRATE = '/pentapod/tcp_state_fullrate'
EXCITATION = '/pentapod/excitation'
PMA_STATE = '/pentapod/pma/state'
#: State of the cutting process, one message per step (layout in the module docstring).
CUTTING_STATE = '/pentapod/cutting/state'
#: The cutting run's operation, published once (std_msgs/String, reliable, transient local,
#: depth 1): the JSON text of :func:`pentapod_sim.machining.cutting_spec.spec_message`.
#: One cutting node per run (one spindle): both topics have one writer.
CUTTING_SPEC = '/pentapod/cutting/spec'
#: Joint-name prefix of the teeth on :data:`CUTTING_STATE` (``tooth_1`` ... ``tooth_N``).
TOOTH_PREFIX = 'tooth_'
#: Run status of the plant (diagnostic_msgs/DiagnosticStatus, reliable, transient local):
#: ``running`` at the start and every ``status_period`` s of wall time during the run,
#: ``finished`` or ``stopped`` with the steps run at the end; see :data:`RUN_STATUS_KEYS`,
#: :data:`RUN_PROGRESS_KEYS` and docs/recording.md.
RUN_STATUS = '/pentapod/run_status'
#: A force source ``<name>`` publishes on ``FORCE_PREFIX + <name>``.
FORCE_PREFIX = '/pentapod/forces/'
#: A force source ``<name>`` publishes the linear model of its law once, on
#: ``CONTROLLER_MODEL_PREFIX + <name>`` (std_msgs/String, reliable, transient local, depth 1, so a
#: plant started later still gets it): the JSON text of
#: :meth:`pentapod_sim.sim.controllers.DiscreteController.to_json`, :data:`NO_FEEDBACK` for an
#: open-loop source, or :data:`NO_LINEAR_MODEL` and the reason. The plant's truncation check at
#: start-up closes the sampled loop with these models (:mod:`pentapod_sim.nodes.loop_check`).
CONTROLLER_MODEL_PREFIX = '/pentapod/controller_models/'
#: Source ``<name>`` publishes each parameter change during a run on ``PARAMETER_CHANGE_PREFIX +
#: <name>`` (diagnostic_msgs/DiagnosticArray): keys ``<parameter>.old``, ``.new``, ``step`` (the
#: first step computed with it); stamped t_k of that step, so a bag holds it at that time.
PARAMETER_CHANGE_PREFIX = '/pentapod/parameter_changes/'
#: Model text of a source that reads no plant output (an exciter): it closes no loop.
NO_FEEDBACK = 'no feedback'
#: Start of the model text of a source whose law has no linear model (limits, ...).
NO_LINEAR_MODEL = 'no linear model'
#: An exciter ``<name>`` publishes the parameters of its signal once, on
#: ``EXCITATION_SPEC_PREFIX + <name>`` (std_msgs/String, reliable, transient local, depth 1, so a
#: recorder started later still records it): the JSON text of
#: :func:`pentapod_sim.sim.excitation_spec.spec_message`, which
#: :func:`pentapod_sim.analysis.bag.excitation_record.excitation_of` reads back from a bag.
EXCITATION_SPEC_PREFIX = '/pentapod/excitation_spec/'
#: Channels only the live view serves (Foxglove WebSocket, not ROS topics): its derived data;
#: and the plant's display batches, ROS topics only the live view reads (a recorder skips them).
LIVE_PREFIX = '/pentapod/live/'
#: The plant's display batch of a per-step topic ``/pentapod/<name>`` is
#: ``DISPLAY_BATCH_PREFIX + <name>`` (:func:`display_batch_topic`).
DISPLAY_BATCH_PREFIX = LIVE_PREFIX + 'batch/'
#: Run status (sensor_msgs/JointState, one joint per figure: pentapod_sim.live.status).
LIVE_STATUS = '/pentapod/live/status'
#: Running amplitude spectrum of the TCP response: ``TCP_SPECTRUM_PREFIX + 'frequency'`` [Hz]
#: and ``TCP_SPECTRUM_PREFIX + <joint>`` (tcp_x, ...) [m], std_msgs/Float64MultiArray each.
TCP_SPECTRUM_PREFIX = '/pentapod/live/tcp_spectrum/'

JOINT_STATE = 'sensor_msgs/msg/JointState'
WRENCH_STAMPED = 'geometry_msgs/msg/WrenchStamped'
CLOCK_TYPE = 'rosgraph_msgs/msg/Clock'
FLOAT64_MULTI_ARRAY = 'std_msgs/msg/Float64MultiArray'
DIAGNOSTIC_STATUS = 'diagnostic_msgs/msg/DiagnosticStatus'
STRING = 'std_msgs/msg/String'
#: Message type of every fixed data topic (force topics are JOINT_STATE; RUN_STATUS is
#: DIAGNOSTIC_STATUS).
TOPIC_TYPES = {CLOCK: CLOCK_TYPE, TCP_STATE: JOINT_STATE, STRUT_STATES: JOINT_STATE,
               TCP_STATE_FULLRATE: JOINT_STATE, PMA_MOUNT_STATE: JOINT_STATE,
               EXCITATION: WRENCH_STAMPED, PMA_STATE: JOINT_STATE,
               CUTTING_STATE: JOINT_STATE, CUTTING_SPEC: STRING}
#: Topics that carry one message per plant step (stamp t_k) when they are published at all;
#: force topics (:data:`FORCE_PREFIX`) do too. The recorder expects one message per step on them.
STEP_TOPICS = (CLOCK, *STATE_TOPICS, TCP_STATE_FULLRATE, EXCITATION, PMA_STATE,
               CUTTING_STATE)

#: Values of the ``state`` key of a run-status message (DiagnosticStatus.message holds it too).
RUN_RUNNING, RUN_FINISHED, RUN_STOPPED = 'running', 'finished', 'stopped'
#: Keys of a run-status message: ``state`` (see above), ``steps`` (steps run: stamps
#: t_0 ... t_{steps-1} were published), ``dt`` [s], ``last_stamp_ns`` (stamp of the last step,
#: -1 for none) and ``step_topics`` (comma-separated topics the plant published or awaited
#: every step: /clock, its state topics with subscribers, its sources' force topics).
RUN_STATUS_KEYS = ('state', 'steps', 'dt', 'last_stamp_ns', 'step_topics')
#: Further keys of every run-status message (readers must not require them: older bags lack
#: them): ``step_rate`` (steps per second of wall time since the previous status message; 0 in
#: the first), ``deadline_misses`` (realtime: answers of a source that missed the end of their
#: period so far, summed over the sources; 0 in lockstep) and ``rejected_messages`` (force
#: messages the plant rejected so far) and ``rejected_by_reason`` (``source/reason=count``,
#: comma-separated; ``stale`` and ``duplicate``: expected copies of re-published steps), and
#: ``initial_state`` (``rest``, or ``file <path>``: the plant started from the state in that
#: file, parameter ``initial_state_file``; the recorder stores it in the bag's metadata) and
#: ``drives`` (``none``, or ``<file> on struts [...]``: the plant steps the feed drives' rotors,
#: parameter ``drives``; stored in the bag's metadata too).
RUN_PROGRESS_KEYS = ('step_rate', 'deadline_misses', 'rejected_messages', 'rejected_by_reason',
                     'initial_state', 'drives')


def force_topic(source: str) -> str:
    """Topic of the force source ``source``."""
    return FORCE_PREFIX + source


def controller_model_topic(source: str) -> str:
    """Topic of the linear model of the force source ``source``."""
    return CONTROLLER_MODEL_PREFIX + source


def excitation_spec_topic(source: str) -> str:
    """Topic of the signal parameters of the exciter ``source``."""
    return EXCITATION_SPEC_PREFIX + source


def is_step_topic(topic: str) -> bool:
    """True for a topic that carries one message per step (:data:`STEP_TOPICS`, forces)."""
    return topic in STEP_TOPICS or topic.startswith(FORCE_PREFIX)


def cutting_joints(teeth: int) -> list[str]:
    """Joint names of the teeth on :data:`CUTTING_STATE`: ``tooth_1`` ... ``tooth_<teeth>``."""
    return [f'{TOOTH_PREFIX}{j}' for j in range(1, teeth + 1)]


def tcp_spectrum_topic(name: str) -> str:
    """Live-view channel of the TCP spectrum: ``'frequency'`` or a TCP joint name."""
    return TCP_SPECTRUM_PREFIX + name


def has_display_batch(topic: str) -> bool:
    """True for a per-step topic whose values the plant also publishes in display batches."""
    return topic in STATE_TOPICS or topic.startswith(FORCE_PREFIX)


def display_batch_topic(topic: str) -> str:
    """The display-batch topic of a state or force topic (ValueError for other topics)."""
    if not has_display_batch(topic):
        raise ValueError(f'{topic} has no display batch (state and force topics have)')
    return DISPLAY_BATCH_PREFIX + topic[len(NAMESPACE):]


def batched_topic(topic: str) -> str | None:
    """The per-step topic a display-batch topic carries; None for any other topic."""
    if not topic.startswith(DISPLAY_BATCH_PREFIX):
        return None
    origin = NAMESPACE + topic[len(DISPLAY_BATCH_PREFIX):]
    return origin if has_display_batch(origin) else None


def is_testbed_topic(topic: str) -> bool:
    """True for /clock and every topic under the testbed namespace."""
    return topic == CLOCK or topic.startswith(NAMESPACE)


@dataclass(frozen=True)
class QosSpec:
    """
    QoS of one class of topics, as plain data (every testbed topic is reliable).

    Attributes
    ----------
    depth : int
        KEEP_LAST history depth [messages]: how far a slow reader may fall behind before a
        reliable writer drops its oldest unacknowledged message.
    """

    depth: int
    reliability: str = 'reliable'
    durability: str = 'volatile'


#: Durability the per-step streams' writers offer. Transient local: a recorder (reliable,
#: transient local reader) that matches a writer late still gets every step in the writer's
#: history. Discovery is not symmetric: a source started before the recorder saw the
#: recorder's reader within a second and answered, while the recorder found the source's
#: writers 4-5 s later; a volatile reader then drops what came before and the bag lacked the
#: source's first 2,000-2,700 steps. Readers that want only new steps (the plant's force
#: subscriptions, the sources' state subscriptions, controllers) subscribe volatile
#: (``pentapod_sim.nodes.common.qos(kind, fresh=True)``).
STREAM_DURABILITY = 'transient_local'


#: Highest sample rate [Hz] of the shipped configurations (config/scenarios/*.yaml: 5 kHz,
#: config/study.yaml: 3 kHz; test/test_recording_stalls.py checks them). A lockstep run with a
#: controller steps slower (about 2,000 steps/s here), a realtime run at the sample rate.
MAX_SHIPPED_RATE = 5000.0
#: Wall time [s] a recorder may stall (SIGSTOP, swapping, a busy disk) without losing a message.
RECORDER_STALL = 5.0
#: Extra wall time [s] the history must cover after a stall until the reader has asked for what
#: it missed: Fast DDS repairs after the writer's next heartbeat, every 3 s by default. The
#: package's local profile (config/dds/loopback.xml) sends one every 0.1 s, so a local run has
#: this margin to spare; 3 s holds for any other profile (a network) too.
REPAIR_TIME = 3.0
#: History depth [messages] of every per-step stream (states, /clock, forces, excitation, PMA
#: state): (RECORDER_STALL + REPAIR_TIME) s at MAX_SHIPPED_RATE = 40,000 messages. A reliable
#: KEEP_LAST writer drops its oldest message, acknowledged or not, when its history is full.
STREAM_DEPTH = int(math.ceil((RECORDER_STALL + REPAIR_TIME) * MAX_SHIPPED_RATE))
#: QoS per class of topic: plant outputs and /clock ('state'), forces from the sources
#: ('force'; one message per step), diagnostics such as PMA state and excitation ('info'), the
#: run status ('status': the last one kept for a late reader) and the sources' controller models
#: ('model': published once, kept for a late reader), the exciters' signal parameters
#: ('spec': published once, kept for a late reader), parameter changes during a run
#: ('change': kept for a late reader) and the plant's display batches
#: ('display': one message per ``display_batch_period``, read best effort by the live view).
QOS = {'state': QosSpec(STREAM_DEPTH, durability=STREAM_DURABILITY),
       'force': QosSpec(STREAM_DEPTH, durability=STREAM_DURABILITY),
       'info': QosSpec(STREAM_DEPTH, durability=STREAM_DURABILITY),
       'status': QosSpec(4, durability='transient_local'),
       'model': QosSpec(1, durability='transient_local'),
       'spec': QosSpec(1, durability='transient_local'), 'display': QosSpec(100),
       'change': QosSpec(100, durability='transient_local')}


def qos_class(topic: str) -> str | None:
    """Class of :data:`QOS` the testbed's publishers of ``topic`` use (None: not a testbed one)."""
    if topic in (CLOCK, *STATE_TOPICS, TCP_STATE_FULLRATE):
        return 'state'
    if topic.startswith(FORCE_PREFIX):
        return 'force'
    if topic in (EXCITATION, PMA_STATE, CUTTING_STATE):
        return 'info'
    if topic.startswith(CONTROLLER_MODEL_PREFIX):
        return 'model'
    if topic.startswith(EXCITATION_SPEC_PREFIX) or topic == CUTTING_SPEC:
        return 'spec'
    if topic.startswith(PARAMETER_CHANGE_PREFIX):
        return 'change'
    if batched_topic(topic) is not None:
        return 'display'
    return 'status' if topic == RUN_STATUS else None


def is_latched(topic: str) -> bool:
    """True for a testbed topic whose publishers keep messages for late readers."""
    kind = qos_class(topic)
    return kind is not None and QOS[kind].durability == 'transient_local'


def _table() -> dict[str, tuple[str, str, str]]:
    """Map output port -> (topic, joint name, 'position' | 'velocity' | 'effort')."""
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
        # the feed-drive line of the strut (strut against its gimbal, across the drive link);
        # its load cell sits in series with it, so it reads the force through this joint
        # (the axial joint is the BP cardan ring, another joint of the strut)
        table[f'strut{i}_drive_displacement'] = (STRUT_STATES, f'strut{i}_drive', 'position')
        table[f'strut{i}_drive_velocity'] = (STRUT_STATES, f'strut{i}_drive', 'velocity')
        table[f'strut{i}_force'] = (STRUT_STATES, f'strut{i}_drive', 'effort')
        # the motor encoder of a plant with the feed drives' rotors (plant parameter drives):
        # the rotor along the strut, relative to the gimbal
        table[f'strut{i}_motor_position'] = (STRUT_STATES, f'strut{i}_motor', 'position')
        table[f'strut{i}_motor_velocity'] = (STRUT_STATES, f'strut{i}_motor', 'velocity')
        for k in (2, 3):
            table[f'strut{i}_chord_{k}'] = (STRUT_STATES, f'strut{i}_chord_{k}', 'position')
            table[f'strut{i}_chord_velocity_{k}'] = (STRUT_STATES, f'strut{i}_chord_{k}',
                                                     'velocity')
    return table


PORT_LOCATION = _table()


def port_location(port: str) -> tuple[str, str, str]:
    """Return (topic, joint, field) carrying an output port (PortError if none)."""
    try:
        return PORT_LOCATION[port]
    except KeyError:
        raise PortError(f'output port {port!r} is not published in any state topic') from None


def state_layouts(output_names: Sequence[str]) -> list[TopicLayout]:
    """Layouts of the state topics that carry at least one of the model's outputs."""
    index = {n: i for i, n in enumerate(output_names)}
    joints: dict[str, dict[str, dict[str, int]]] = {t: {} for t in STATE_TOPICS}
    for port in output_names:
        if port not in PORT_LOCATION:
            continue
        topic, joint, kind = PORT_LOCATION[port]
        joints[topic].setdefault(joint, {})[kind] = index[port]
    def column(table: dict[str, dict[str, int]], kind: str) -> npt.NDArray[np.intp]:
        return np.array([fields.get(kind, -1) for fields in table.values()], dtype=np.intp)
    return [TopicLayout(topic, list(table), column(table, 'position'),
                        column(table, 'velocity'), column(table, 'effort'))
            for topic, table in joints.items() if table]


def fullrate_layout(output_names: Sequence[str], substeps: int) -> TopicLayout | None:
    """
    Layout of :data:`TCP_STATE_FULLRATE` on the flattened (N, n_out) full-rate outputs.

    Joint ``tcp_<axis>@<j>`` of substep j takes its position and velocity from row j; None if
    the model has no TCP output.
    """
    tcp = next((lay for lay in state_layouts(output_names) if lay.topic == TCP_STATE), None)
    if tcp is None:
        return None
    return batch_layout(tcp, len(output_names), substeps, TCP_STATE_FULLRATE)


def stamp_ns(step: int, dt: float) -> int:
    """Time stamp of step k [ns], t_k = k dt rounded to whole nanoseconds."""
    return int(round(step * dt * 1e9))


def step_of(stamp: int, dt: float) -> int:
    """Step index of a stamp [ns] (inverse of :func:`stamp_ns` for dt >= 1 ns)."""
    return int(round(stamp / (dt * 1e9)))
