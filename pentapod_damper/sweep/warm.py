"""
Warm-up of a sweep worker: import the pose code before the first task, and time it.

Kept apart from the runner and the pose code so that unpickling :func:`import_seconds` on a
worker imports nothing heavy: the time it returns is the import of :data:`WORKER_MODULE`
itself (0 s in a worker forked from a client that has it already).
"""
from __future__ import annotations

import importlib
import time

#: Module a worker needs for a pose (the task function lives there).
WORKER_MODULE = 'pentapod_damper.sweep.compute'


def import_seconds() -> float:
    """Seconds this process takes to import :data:`WORKER_MODULE` (about 0 if it had it)."""
    t0 = time.perf_counter()
    importlib.import_module(WORKER_MODULE)
    return time.perf_counter() - t0
