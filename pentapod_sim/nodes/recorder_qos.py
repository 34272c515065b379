"""
The QoS of a recorder's subscriptions, and what its bag stores of the publishers' QoS.

A recorder subscribes each topic at the highest level every known publisher matches
(:func:`level_for`), and re-subscribes lower when a publisher that offers less joins
(:meth:`pentapod_sim.nodes.recorder_node.RecorderNode.discover`). The bag keeps each
publisher's offered profile as rosbag2 does (:func:`offered_qos`).
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from pentapod_sim import interface
from pentapod_sim.recording import qos_profile

#: Levels of a recorder subscription, each matching every publisher the next one matches:
#: best effort and volatile (any publisher), reliable and volatile, reliable and transient
#: local (gets a writer's history when it matches late; only transient-local writers).
BEST_EFFORT, RELIABLE, LATE_JOINER = 0, 1, 2
LEVELS = {BEST_EFFORT: 'best effort', RELIABLE: 'volatile', LATE_JOINER: 'transient local'}


def level_for(topic: str, publishers, fresh: bool = False) -> int:
    """
    The highest level that matches every one of ``publishers`` (no publisher: the topic's).

    ``fresh``: volatile at most, none of the writers' history (a source that outlives runs,
    such as a node the judge did not start, holds the answers of its earlier runs).

    Transient local only for topics whose testbed writers offer it
    (:func:`pentapod_sim.interface.is_latched`) and only while every publisher does.
    """
    if any(p.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for p in publishers):
        return BEST_EFFORT
    if not fresh and interface.is_latched(topic) and all(
            p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers):
        return LATE_JOINER
    return RELIABLE


def subscription_qos(level: int, depth: int) -> QoSProfile:
    """The profile of a subscription at ``level`` (:func:`level_for`), ``depth`` kept."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=(ReliabilityPolicy.BEST_EFFORT if level == BEST_EFFORT
                                   else ReliabilityPolicy.RELIABLE),
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if level == LATE_JOINER
                                  else DurabilityPolicy.VOLATILE))


def offered_qos(topic: str, profile) -> dict:
    """
    The rosbag2 QoS entry of one publisher of ``topic``.

    Reliability and durability come from discovery. DDS discovery does not carry the history
    depth (rmw reports 0, history unknown), so a testbed topic gets the depth its publishers
    use (:data:`pentapod_sim.interface.QOS`), another topic rosbag2's unknown/0.
    """
    kind = interface.qos_class(topic)
    entry = qos_profile(profile.reliability.name.lower(),
                        interface.QOS[kind].depth if kind else 0,
                        profile.durability.name.lower())
    if kind is None:
        entry['history'] = 'unknown'
    return entry
