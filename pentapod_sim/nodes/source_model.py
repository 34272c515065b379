"""
A force source's side of the plant's truncation check: it publishes the linear model of its law.

Every force source publishes the linear model of its law once, on
``/pentapod/controller_models/<source>`` (:func:`pentapod_sim.interface.controller_model_topic`;
std_msgs/String, reliable, transient local, depth 1, so a plant started later still gets it):
the JSON text of :meth:`pentapod_sim.sim.controllers.DiscreteController.to_json`,
``no feedback`` for a source that reads no plant output (the exciter), or ``no linear model:
<reason>`` (a PMA with limits). :class:`pentapod_sim.nodes.lockstep_source.LockstepSource`
publishes it for every testbed source; a user's controller may publish one the same way with
:func:`publish_model`. The plant's side (collecting the models, closing the loop on the FE
check model) is :mod:`pentapod_sim.nodes.loop_check`; this module imports nothing of it, so a
source node never loads the FE model code (test/test_layout.py checks that).
"""
from __future__ import annotations

from typing import Callable

from std_msgs.msg import String

from pentapod_sim.errors import ConfigError
from pentapod_sim.interface import controller_model_topic, NO_FEEDBACK, NO_LINEAR_MODEL
from pentapod_sim.nodes.common import qos
from pentapod_sim.sim.controllers import DiscreteController

#: QoS of the model topics (publishers and the plant's subscriptions).
MODEL_QOS = qos('model')


def model_text(linear_model: Callable[[], DiscreteController], feedback: bool = True) -> str:
    """
    The message text of a source's law (see the module docstring).

    Parameters
    ----------
    linear_model : callable
        Returns the law's DiscreteController; a ConfigError says why it has none.
    feedback : bool
        False for a source that reads no plant output (``no feedback``).
    """
    if not feedback:
        return NO_FEEDBACK
    try:
        return linear_model().to_json()
    except ConfigError as err:
        return f'{NO_LINEAR_MODEL}: {err}'


def publish_model(node, source_name: str, text: str):
    """Publish ``text`` once on the source's latched model topic; return the publisher."""
    pub = node.create_publisher(String, controller_model_topic(source_name), MODEL_QOS)
    pub.publish(String(data=text))
    return pub
