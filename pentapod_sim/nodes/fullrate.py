"""
Full-rate outputs of a multi-rate plant node (trace, batched topic); the display batches.

With ``substeps`` N > 1 the plant integrates N exact ZOH substeps per exchange
(:class:`pentapod_sim.sim.multirate.MultiRatePlant`); the states go out once per exchange as
usual. The N full-rate outputs of exchange k depend on u_k, so they exist once the forces of the
exchange are in: :meth:`FullRateOutputs.record` computes them then (only if the trace keeps
them or someone subscribes) and publishes the TCP samples as *one* sensor_msgs/JointState on
:data:`pentapod_sim.interface.TCP_STATE_FULLRATE` (stamp t_k, joints ``tcp_{x,y,z}@j``).

Why one JointState per exchange: it carries the stamp, so the recorder logs it at sim time and
waits for its last step like the other per-step topics, and the bag readers know the type. One
pre-built message with 3N joints costs about 31 us per exchange with a subscriber here, a
std_msgs/Float64MultiArray (no stamp) 21 us, N JointStates per exchange 1,300-1,900 us
(N = 10; /tmp measurement, see the report of issue 12 item 3).

The same per-step hook feeds the plant's display batches (:mod:`.display_batch`): every
``display_batch_period`` one message per state topic and per force source, for the live view,
published only while subscribed.
"""
from __future__ import annotations

import array

import numpy as np
from sensor_msgs.msg import JointState

from pentapod_sim.interface import fullrate_layout, stamp_ns, TCP_STATE_FULLRATE
from pentapod_sim.nodes.common import stamp_msg, STATE_QOS
from pentapod_sim.nodes.display_batch import DisplayBatches


class FullRateOutputs:
    """
    The plant node's full-rate outputs (none for a single-rate plant) and display batches.

    Parameters
    ----------
    node : rclpy.node.Node
        The plant node (creates the publishers: the full-rate one when N > 1).
    core : DiscretePlant or MultiRatePlant
        The plant core.
    mixer : ForceMixer
        The plant's force mixer (the display batches of the sources' forces).
    display_period : float
        Simulated time per display batch [s] (parameter ``display_batch_period``).
    """

    def __init__(self, node, core, mixer, display_period: float):
        self.core = core
        self.substeps = getattr(core, 'substeps', 1)
        self.layout = (fullrate_layout(core.output_names, self.substeps)
                       if self.substeps > 1 else None)
        self.pub = (node.create_publisher(JointState, TCP_STATE_FULLRATE, STATE_QOS)
                    if self.layout is not None else None)
        self.msg = JointState(name=self.layout.joints) if self.layout else None
        self.active = False
        self._rows = np.empty((self.substeps, len(core.output_names)))
        self.display = DisplayBatches(node, core, mixer, display_period)
        self._context = node.context

    def refresh(self) -> None:
        """Note whether the topics have subscribers (called with the plant's own refresh)."""
        self.active = self.pub is not None and self.pub.get_subscription_count() > 0
        self.display.refresh()

    def publishers(self) -> list:
        """The publishers (for the plant's subscriber waits and acks)."""
        return ([self.pub] if self.pub is not None else []) + self.display.publishers

    def topics(self) -> list[str]:
        """The per-step topic (N > 1), published or not."""
        return [self.pub.topic_name] if self.pub is not None else []

    def active_topics(self) -> list[str]:
        """The per-step topic, if it is published every exchange now."""
        return [self.pub.topic_name] if self.active else []

    def display_batches(self) -> tuple[list, int]:
        """The display-batch publishers and the number of batches published."""
        return self.display.publishers, self.display.published

    def flush(self) -> None:
        """Publish the open display batch (the run ended; not after the context shut down)."""
        if self._context.ok():
            self.display.flush()

    def record(self, k: int, y: np.ndarray, u: np.ndarray, trace) -> None:
        """
        Record exchange k: trace, display batches, and the full-rate outputs if wanted.

        Call between ``outputs`` (y_k) and ``advance`` (u_k). The full-rate outputs are
        computed only if the trace keeps them or the topic has a subscriber.
        """
        trace.record(k, y, u)
        self.display.record(k, y)
        kept = trace.fine_rows(k)
        if not self.active and kept is None:
            return
        rows = kept if kept is not None else self._rows
        self.core.fine_outputs(u, y, rows)
        if self.active:
            pos, vel, eff = self.layout.values(rows.reshape(-1))
            msg = self.msg
            msg.position = array.array('d', pos.tobytes())
            msg.velocity = array.array('d', vel.tobytes())
            msg.effort = array.array('d', eff.tobytes())
            msg.header.stamp = stamp_msg(stamp_ns(k, self.core.dt))
            self.pub.publish(msg)
