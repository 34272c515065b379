"""
Display batches of a plant node: its per-step values, M steps per message, for the live view.

A live plot shows a run at about 100 Hz; the plant steps at 3-5 kHz. Were the live view to
subscribe to the per-step state and force topics, the plant would serialise and publish every
state topic every step just for it (it publishes a state topic only while someone subscribes:
:class:`pentapod_sim.nodes.local_bus.Outlet`), the sources would send every force twice, and
the view's process would take 5,000 messages a second per topic off DDS, all on the cores the
lockstep loop runs on. Instead the plant collects what it has anyway (y_k, and the force of
each source the :class:`~pentapod_sim.sim.stepping.ForceMixer` holds for step k) and, while
someone subscribes, publishes every M steps one sensor_msgs/JointState per state topic and per
force source on :func:`pentapod_sim.interface.display_batch_topic` (``/pentapod/live/batch/...``):

* joints ``<joint>@j`` (j = 0..M-1, step k0 + j of the batch; the layout of the full-rate
  topic, :func:`pentapod_sim.topic_layout.batch_layout`), the per-step topic's fields: position
  and velocity of the state topics (and effort where the topic has one), effort of a source's
  force (its ports in the order of its messages);
* header.stamp t_k0; header.frame_id the step dt [s] as ``repr(dt)``, so a reader gets the
  stamp of sample j exactly, ``stamp_ns(k0 + j, dt)`` with ``k0 = step_of(stamp, dt)``.

M = round(``display_batch_period`` / dt) (plant parameter). A batch ends early at the end of the
run (:meth:`DisplayBatches.flush`) and when a source changes its ports. The values are the ones
the per-step topics carry, bit for bit (the state topics' from the same y_k; in lockstep a
source's force for step k is its answer to step k; in real time, the force the plant applied,
a held one if the answer was late). Messages are serialised with the cached names block of
:class:`pentapod_sim.nodes.wire_cdr.JointStateCdr` and published raw: about 20 us per message
of 1,250 joints here, against 110 us through rclpy's message conversion.
"""
from __future__ import annotations

import array
from typing import Any

import numpy as np
from sensor_msgs.msg import JointState

from pentapod_sim.interface import (
    display_batch_topic,
    force_topic,
    stamp_ns,
    state_layouts,
)
from pentapod_sim.nodes.common import qos, stamp_msg
from pentapod_sim.nodes.wire_cdr import JointStateCdr
from pentapod_sim.topic_layout import batch_layout, TopicLayout


class DisplayBatches:
    """
    The plant's display-batch publishers and the samples of the open batch.

    Parameters
    ----------
    node : rclpy.node.Node
        The plant node (creates the publishers).
    core : DiscretePlant or MultiRatePlant
        The plant core (output names, dt).
    mixer : ForceMixer
        The plant's force mixer (its sources and their held forces).
    period : float
        Simulated time per batch [s]; M = max(1, round(period / dt)) steps.
    """

    def __init__(self, node, core, mixer, period: float):
        self.dt = core.dt
        self.size = max(1, int(round(period / core.dt)))
        self.mixer = mixer
        n_out, n_in = len(core.output_names), len(mixer.input_names)
        profile = qos('display')
        self.states = [(node.create_publisher(JointState, display_batch_topic(lay.topic),
                                              profile), lay)
                       for lay in state_layouts(core.output_names)]
        self.forces = {name: node.create_publisher(JointState,
                                                   display_batch_topic(force_topic(name)),
                                                   profile)
                       for name in mixer.sources}
        self.y = np.empty((self.size, n_out))
        self.u = {name: np.empty((self.size, n_in)) for name in mixer.sources}
        # ports of each source's forces in the open batch (() before its first answer)
        self.ports: dict[str, tuple[str, ...]] = dict.fromkeys(mixer.sources, ())
        self.active: list = []            # publishers with a subscriber
        self.k0, self.count = 0, 0
        self.published = 0                # messages sent
        self._layouts: dict[tuple, Any] = {}     # (topic or source, ports, samples) -> layout
        self._msg = JointState()
        self._msg.header.frame_id = repr(core.dt)
        self._cdr = JointStateCdr()

    @property
    def publishers(self) -> list:
        """Every display-batch publisher (for the plant's subscriber waits and acks)."""
        return [pub for pub, _ in self.states] + list(self.forces.values())

    def refresh(self) -> None:
        """Note which batches have subscribers; none: drop the open batch."""
        self.active = [pub for pub in self.publishers if pub.get_subscription_count() > 0]
        if not self.active:
            self.count = 0

    def record(self, k: int, y: np.ndarray) -> None:
        """
        Add step k (y_k, and each source's held force for step k); publish a full batch.

        Call once per step after the forces of step k are in. Does nothing while no batch
        has a subscriber.
        """
        if not self.active:
            return
        if self.count and k != self.k0 + self.count:
            self.flush()                  # not the next step: start a new batch
        latest, names = self.mixer.latest, self.mixer.latest_names
        for source, ports in self.ports.items():
            if tuple(names[source]) != ports:
                self.flush()              # a source changed its ports: a new batch
                self.ports = {s: tuple(names[s]) for s in self.ports}
                break
        row = self.count
        if row == 0:
            self.k0 = k
        self.y[row] = y
        for source, rows in self.u.items():
            rows[row] = latest[source]
        self.count += 1
        if self.count == self.size:
            self.flush()

    def flush(self) -> None:
        """Publish the open batch (to the subscribed batches) and start a new one."""
        count, self.count = self.count, 0
        if not count:
            return
        msg = self._msg
        msg.header.stamp = stamp_msg(stamp_ns(self.k0, self.dt))
        for pub, lay in self.states:
            if pub not in self.active:
                continue
            batch = self._layouts.get((lay.topic, count))
            if batch is None:
                batch = self._layouts[(lay.topic, count)] = batch_layout(
                    lay, self.y.shape[1], count, pub.topic_name)
            pos, vel, eff = batch.values(self.y[:count].reshape(-1))
            msg.name = batch.joints
            msg.position = array.array('d', pos.tobytes())
            msg.velocity = array.array('d', vel.tobytes())
            msg.effort = array.array('d', eff.tobytes())
            self._publish(pub, msg)
        msg.position, msg.velocity = array.array('d'), array.array('d')
        for source, pub in self.forces.items():
            if pub not in self.active or not self.ports[source]:
                continue                  # not subscribed, or no answer yet
            key = (source, self.ports[source], count)
            if (got := self._layouts.get(key)) is None:
                got = self._layouts[key] = self._force_layout(self.ports[source], count)
            msg.name = got.joints
            msg.effort = array.array(
                'd', self.u[source][:count].reshape(-1)[got.index('effort')].tobytes())
            self._publish(pub, msg)

    def _force_layout(self, ports: tuple[str, ...], count: int) -> TopicLayout:
        """Joints ``<port>@j``; effort indices into the flattened (count, n_in) forces."""
        columns = np.array([self.mixer.input_names.index(p) for p in ports], dtype=np.intp)
        none = np.full(columns.size, -1, dtype=np.intp)
        one = TopicLayout('', list(ports), none, none, columns)
        return batch_layout(one, len(self.mixer.input_names), count, '')

    def _publish(self, pub, msg: JointState) -> None:
        pub.publish(self._cdr(msg))
        self.published += 1
