"""
The reference paper's damping study, run end to end on the testbed.

For each machine position and scenario (baseline, strut bending damping on all struts and on
struts 1-2, axial damping, TCP damping, two proof-mass actuators) the study runs the plant,
exciter, controller and recorder nodes in lockstep, records an MCAP bag, estimates the TCP
FRF from it, compares it with the analytic closed-loop FRF of the same model, and writes a
report (Markdown + PNG + CSV). ``python -m pentapod_damper.study`` (``tools/study.sh``).
"""
