"""
Pentapod virtual testbed: FE model, modal analysis, reduced plant and its ROS 2 nodes.

The numerical modules (model, kinematics, modal analysis, reduction, state space, analysis)
import neither rclpy nor any message package; only ``pentapod_sim.nodes`` does.
"""

__version__ = '0.1.0'
