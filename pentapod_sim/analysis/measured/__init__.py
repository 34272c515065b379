"""
Measured data in, model modes out: FRFs from UFF 58 and CSV, DOF labels, UFF 55 mode shapes.

A measured DOF is labelled ``POINT:COMP`` (a named point of the model, e.g. ``tcp:+y``),
``NODE:COMP`` (an FE node label, e.g. ``1042:-z``) or a port name (``tcp_force_y``,
``strut1_bending_2``); :mod:`~pentapod_sim.analysis.measured.model_dofs` turns labels into
observation rows of the model. UFF files number their nodes; the calibration settings map
those numbers to points or FE nodes.
"""
