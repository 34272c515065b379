"""
Workspace sweep: the machine's dynamics and the dampers' benefit over many poses, on Dask.

Per pose (:mod:`pentapod_damper.sweep.compute`): FE model, cause of the first frame and strut
modes, reduced plant, and the analytic continuous closed loop of each damping scenario (the
study's functions). Poses run as Dask tasks (:mod:`pentapod_damper.sweep.runner`); each
finished task is one Parquet file of the result dataset (:mod:`pentapod_damper.sweep.store`),
so an interrupted sweep resumes where it stopped. ROS-free. Usage: docs/sweep.md.
"""
