"""
Damper, proof-mass-actuator and active damping laws, free of ROS (the nodes and the offline loop).

A law reads plant output ports (``sensor_ports``) and drives plant input ports
(``actuator_ports``). ``step`` is called once per plant step k with the outputs y_k and
returns u_k for its actuator ports (lockstep convention of docs/architecture.md): sampled
feedback with a zero-order hold, u_k answers y_k. Laws with memory offer their discrete state
space from ``discrete_model()``; memoryless linear laws their gain matrix from
``linear_gain()``.

* :mod:`.viscous`: viscous velocity feedback (strut bending, chord, axial, TCP), optionally
  through actuator/sensor dynamics (:class:`Dynamics`);
* :mod:`.pma`: the ideal proof-mass actuator, optionally with a high-pass and limits;
* :mod:`.linear`: integral force feedback, band-pass velocity, lag displacement and positive
  position feedback, the feed drives' cascade with IFF inside (HAC-LAC) (docs/dampers.md).

Units: forces N, moments N m, velocities m/s, angular rates rad/s, masses kg, gains as stated.
"""
from pentapod_damper.laws.linear import (  # noqa: F401 (the package's API)
    band_pass_velocity,
    feed_drives,
    integral_force_feedback,
    lag_displacement_feedback,
    positive_position_feedback,
    SteppedLaw,
)
from pentapod_damper.laws.pma import ProofMassActuator  # noqa: F401
from pentapod_damper.laws.viscous import (  # noqa: F401
    chord_damper,
    strut_axial_damper,
    strut_bending_damper,
    tcp_damper,
    ViscousDamper,
)
from pentapod_sim.sim.law_models import Dynamics, FILTER_ORDERS, HOLDS  # noqa: F401

__all__ = ['band_pass_velocity', 'chord_damper', 'Dynamics', 'feed_drives', 'FILTER_ORDERS',
           'HOLDS',
           'integral_force_feedback', 'lag_displacement_feedback', 'positive_position_feedback',
           'ProofMassActuator', 'SteppedLaw', 'strut_axial_damper', 'strut_bending_damper',
           'tcp_damper', 'ViscousDamper']
