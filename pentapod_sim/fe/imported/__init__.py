"""
FE models of other codes: M and K (and node coordinates with the DOF map) from matrix files.

A small YAML file describes the machine (:mod:`~pentapod_sim.fe.imported.description`): the
matrix files and their format, the unit system, the node coordinates and which nodes are the
named points of docs/architecture.md (TCP, strut ends, joints), from which the plant's ports
follow. :func:`~pentapod_sim.fe.imported.build.load_fe_model` turns it into the
:class:`~pentapod_sim.fe.model.FEModel` the rest of the chain (modes, causes, reduction, plant)
consumes unchanged. Formats (one module each, reader and writer side by side):

* Matrix Market (``scipy.io.mmread`` / ``mmwrite``) with a DOF map CSV,
* Abaqus ``*MATRIX GENERATE`` / ``*MATRIX OUTPUT, FORMAT=MATRIX INPUT`` text (``.mtx``),
* ANSYS MAPDL ``.full`` through the optional package ansys-mapdl-reader (read only).

:func:`~pentapod_sim.fe.imported.export.export_fe_model` writes the project's own model in the
two text formats, with the description that reads it back.
"""
