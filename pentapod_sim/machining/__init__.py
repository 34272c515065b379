"""
Machining: chatter stability of milling and turning at the TCP, without ROS.

In pipeline order: the material and tool table (:mod:`~pentapod_sim.machining.materials`), the
cutter engagement and force law (:mod:`~pentapod_sim.machining.milling_cut`), the TCP FRF
matrix (:mod:`~pentapod_sim.machining.tcp_frf`), stability lobes of the zero-order solution
(:mod:`~pentapod_sim.machining.lobes`), the semi-discretisation check
(:mod:`~pentapod_sim.machining.semi_discretisation`), the regenerative cutting process in the
time domain (:mod:`~pentapod_sim.machining.cutting_process`), chatter seen in a displacement
record (:mod:`~pentapod_sim.machining.chatter`) and the lobe diagram
(:mod:`~pentapod_sim.machining.lobe_plot`). docs/machining.md has the formulas, conventions
and where each method is valid.
"""
