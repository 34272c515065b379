"""
The reference paper's damping study, run end to end on the testbed.

For each machine position and scenario (baseline, strut bending damping on all struts and on
struts 1-2, axial damping, TCP damping, two proof-mass actuators) the study runs the plant,
exciter, controller and recorder nodes in lockstep, records an MCAP bag, estimates the TCP
FRF from it, compares it with the analytic closed-loop FRF of the same model, and writes a
report (Markdown + PNG + CSV). ``python -m pentapod_damper.study`` (``tools/study.sh``).

Reading order: :mod:`.schedule` (the stages and what each needs), :mod:`.stages` (each
stage: one function returning one record), :mod:`.records` (the records), :mod:`.tables`
and :mod:`.report` (the tables and report.md made from them), :mod:`.readme` (docs/results.md
and the README's summary). The computations behind the stages: :mod:`.pipeline`,
:mod:`.analytic`, :mod:`.damping`, :mod:`.measured_damping`, :mod:`.bending`, :mod:`.pma`,
:mod:`.figures` and :mod:`.plots`; :mod:`.runs` starts the testbed runs.
"""
