"""
Modal damping calibrated from measured FRFs: identify, pair with the model's modes, fill, report.

Chain (:func:`~pentapod_sim.analysis.calibration.update.calibrate`): poles and modal constants
of the measured FRFs per sub-band (pLSCF + LSFD, :mod:`pentapod_sim.analysis.ema`) -> pairs of
measured and model modes by MAC at the measured DOFs and frequency (Hungarian assignment,
:mod:`~pentapod_sim.analysis.calibration.pairing`) -> measured damping ratio per paired mode,
a Rayleigh fit or per-band values for the others
(:mod:`~pentapod_sim.analysis.calibration.fill`) -> the plant's damping file
(:mod:`pentapod_sim.plant.damping_file`) -> the report: pairing table, overlay of measured and
updated FRFs, remaining error per FRF (:mod:`~pentapod_sim.analysis.calibration.report`).
"""
