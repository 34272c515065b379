"""
Live view of a running testbed (ROS-free parts).

Min/max envelopes at a display rate, a running TCP spectrum, the run status, the Foxglove
WebSocket server and the Foxglove layout. The ROS adapter is
:mod:`pentapod_sim.nodes.live_view_node`; see docs/live_view.md.
"""
