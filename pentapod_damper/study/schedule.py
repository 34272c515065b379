"""
The study as a graph of its stages, run by dask's threaded scheduler.

:func:`study_graph` lists the stages in the order a reader follows the study: per position
its model; per position and scenario the analytic FRFs and loop poles, a random-excitation
testbed run and, for the damping scenarios, a multisine damping run; the PMA step runs and
requirements; per position the bending damper comparison and the damper table's strut laws
(:mod:`pentapod_damper.study.strut_laws`); the figures. Each stage is a
``dask.delayed`` call of a function of :mod:`pentapod_damper.study.stages` on the records of
the stages it needs. :func:`compute` runs the graph on ``jobs`` threads (dask's local
scheduler), starting among the ready stages the one that leads to the longest chain of work
(:func:`critical_path`), and prints one line per finished stage. Threads suffice on two
cores: a testbed run is a child process (one core), and the analytic stages spend their time
in LAPACK, which releases the GIL.

Testbed runs each reserve a free ROS domain, so they run side by side. With ``ROS_DOMAIN_ID``
set (the user's choice of one domain) they form one lane: each run waits for the one before
(an edge of the graph), while the other threads keep the cores busy with analytic stages.

Adding a stage: a function in :mod:`~pentapod_damper.study.stages` returning a record (a
:class:`~pentapod_damper.study.records.Table` for a table the report shows as it is), and one
line in :func:`study_graph` that adds it with the results it needs.

Stopping: a stop signal (:mod:`pentapod_sim.shutdown`: SIGINT, SIGTERM, SIGHUP, recorded by
the handler the study installs) or a failed stage starts no further stage; the running testbed
runs stop their nodes (the scenario runner sees the same request), and once every running
stage has returned the error is raised again, or :class:`Interrupted` for a signal.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields
import math
from pathlib import Path
import signal
import time
from typing import Any, Callable, Mapping

from dask.base import compute as dask_compute
from dask.callbacks import Callback
from dask.delayed import Delayed, delayed

from pentapod_damper.study import figures, machining, stages, strut_laws
from pentapod_damper.study.config import StudyConfig
from pentapod_damper.study.pipeline import scenario_pma
from pentapod_damper.study.records import Figures, FloatArray, Pair, StudyResults
from pentapod_sim import shutdown

#: Stages (their times are summed per stage in the report's Timings).
MODELS, ANALYTIC, BENDING, PMA = ('models', 'analytic FRFs, checks and poles',
                                  'bending dampers', 'PMA requirements')
FRF_RUNS, DAMPING_RUNS, FIGURES = 'FRF and step runs', 'damping runs', 'figures'
LOBES, CUTTING_RUNS = 'stability lobes', 'cutting runs'
STRUT_LAWS = "the damper table's strut laws"
#: Rough time of one task of each stage [s] (the study's timeline.csv on an idle two-core
#: machine). Only their proportions matter: they rank the ready stages by the longest
#: chain of work each leads to (:class:`Progress`), so that the long damping runs and bending
#: comparisons start early instead of leaving one thread alone at the end.
STAGE_COST = {MODELS: 2.0, ANALYTIC: 3.0, BENDING: 21.0, PMA: 2.5, FRF_RUNS: 2.5,
              DAMPING_RUNS: 22.0, FIGURES: 4.0, LOBES: 0.5, CUTTING_RUNS: 10.0,
              STRUT_LAWS: 5.0}


class Interrupted(Exception):
    """A stop signal ended the study; ``code`` is the shell's exit code (128 + signal)."""

    def __init__(self, name: str, code: int):
        super().__init__(f'{name} received: stopped')
        self.code = code


class _Stopped(Exception):
    """Raised by a stage that would start after a stop was requested."""


def _stage(function: Callable[..., Any], *args: Any, after: Any = None) -> Any:
    """Run one stage unless a stop was requested (``after``: a lane's previous stage)."""
    if shutdown.requested():
        raise _Stopped()
    return function(*args)


@dataclass
class Graph:
    """
    The stages of a study as dask.delayed calls, each named ``'<stage>: <what>'``.

    ``lane``: testbed runs one at a time, each after the previous one.
    """

    lane: bool = False
    stage_of: dict[str, str] = field(default_factory=dict)
    _last_run: Delayed | None = None

    def add(self, stage: str, what: str, function: Callable[..., Any], *args: Any) -> Delayed:
        """The call ``function(*args)`` (args may hold results of other stages)."""
        return self._call(stage, what, function, args, None)

    def run(self, stage: str, what: str, function: Callable[..., Any], *args: Any) -> Delayed:
        """A testbed run: on the lane (after the previous run) if there is one."""
        self._last_run = self._call(stage, what, function, args,
                                    self._last_run if self.lane else None)
        return self._last_run

    def _call(self, stage: str, what: str, function: Callable[..., Any], args: tuple[Any, ...],
              after: Delayed | None) -> Delayed:
        key = f'{stage}: {what}'
        if key in self.stage_of:
            raise ValueError(f'two stages are named {key!r}')
        self.stage_of[key] = stage
        call: Delayed = delayed(_stage, pure=False)(function, *args, after=after,
                                                    dask_key_name=key)
        return call


@dataclass
class StudyGraph:
    """The study's stages, keyed like the fields of :class:`StudyResults` they fill."""

    models: dict[str, Delayed] = field(default_factory=dict)
    analytic: dict[Pair, Delayed] = field(default_factory=dict)
    damping_runs: dict[Pair, Delayed] = field(default_factory=dict)
    frf_runs: dict[Pair, Delayed] = field(default_factory=dict)
    step_runs: dict[str, Delayed] = field(default_factory=dict)
    bending: dict[str, Delayed] = field(default_factory=dict)
    pma: dict[str, Delayed] = field(default_factory=dict)
    lobes: dict[Pair, Delayed] = field(default_factory=dict)
    cutting: dict[Pair, Delayed] = field(default_factory=dict)
    figures: list[Delayed] = field(default_factory=list)
    tables: list[Delayed] = field(default_factory=list)
    graph: Graph = field(default_factory=Graph)

    def outputs(self) -> dict[str, Any]:
        """The stages by :class:`StudyResults` field (what :func:`compute` computes)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != 'graph'}


def study_graph(cfg: StudyConfig, out_dir: Path, freq: FloatArray, runs: bool = True,
                lane: bool = False, fe_model: Path | None = None) -> StudyGraph:
    """
    Every stage of the study and what it needs.

    ``runs`` False: analytic stages and figures only (no ROS). ``lane``: testbed runs one at
    a time. ``fe_model``: an imported FE model's description for the (one) position.
    """
    g = StudyGraph(graph=Graph(lane))
    add, run = g.graph.add, g.graph.run
    pairs = [(p, s) for p in cfg.positions for s in cfg.scenarios]
    damped = [(p, s) for p, s in pairs if s in cfg.damping_scenarios] if runs else []
    step = cfg.step_position
    pma = [s for s in cfg.scenarios if scenario_pma(s) is not None] if step in cfg.positions \
        else []
    for pos in cfg.positions:
        g.models[pos] = add(MODELS, pos, stages.build_model, cfg, out_dir, pos, fe_model)
    for pos, scn in pairs:
        g.analytic[pos, scn] = add(ANALYTIC, f'{pos} {scn}', stages.analyse_scenario, cfg,
                                   freq, g.models[pos], scn, (pos, scn) in damped)
    for pos, scn in damped:
        g.damping_runs[pos, scn] = run(DAMPING_RUNS, f'{pos} {scn}', stages.damping_run, cfg,
                                       out_dir, g.models[pos], g.analytic[pos, scn])
    for pos, scn in pairs if runs else []:
        g.frf_runs[pos, scn] = run(FRF_RUNS, f'{pos} {scn}', stages.frf_run, cfg, out_dir,
                                   g.models[pos], g.analytic[pos, scn])
    for scn in pma if runs else []:
        g.step_runs[scn] = run(FRF_RUNS, f'{step} {scn} step', stages.step_run, cfg, out_dir,
                               g.models[step], scn)
    for scn in pma:
        g.pma[scn] = add(PMA, scn, stages.pma_requirements, cfg, freq, g.models[step],
                         g.analytic[step, scn])
    for pos in cfg.positions:
        g.bending[pos] = add(BENDING, pos, stages.bending_dampers, cfg, freq, g.models[pos])
    for pos, scn in pairs:
        g.lobes[pos, scn] = add(LOBES, f'{pos} {scn}', machining.scenario_lobes, cfg,
                                g.models[pos], g.analytic[pos, scn])
    g.tables.append(add(LOBES, 'table', machining.lobes_table, cfg, g.lobes))
    if fe_model is None:        # the table's laws: the own machine's strut ports and table
        laws = {pos: add(STRUT_LAWS, pos, stages.damper_table_laws, cfg, g.models[pos])
                for pos in cfg.positions}
        g.tables.append(add(STRUT_LAWS, 'table', strut_laws.strut_laws_table, cfg, laws))
    for pos, scn in [(p, s) for p, s in pairs if s in cfg.cutting_runs] if runs else []:
        g.cutting[pos, scn] = run(CUTTING_RUNS, f'{pos} {scn}', machining.cutting_check, cfg,
                                  out_dir, g.models[pos], g.analytic[pos, scn],
                                  g.lobes[pos, scn])
    if g.cutting:
        g.tables.append(add(CUTTING_RUNS, 'table', machining.cuts_table, list(g.cutting.values())))
    for pos in cfg.positions:
        g.figures.append(add(FIGURES, pos, figures.position_figures, cfg, out_dir, freq,
                             g.models[pos], _of(g.analytic, pos), _of(g.frf_runs, pos)))
    first = cfg.positions[0]
    g.figures.append(add(FIGURES, 'gain sweeps', figures.sweep_figures, cfg, out_dir,
                         g.bending, _of(g.analytic, first)))
    if g.pma:
        g.figures.append(add(FIGURES, 'PMA requirements', figures.pma_figure, cfg, out_dir,
                             freq, g.pma, _of(g.frf_runs, step)))
    if g.step_runs:
        g.figures.append(add(FIGURES, 'PMA steps', figures.step_figure, cfg, out_dir,
                             g.step_runs))
    for pos in cfg.positions:
        g.figures.append(add(FIGURES, f'lobes {pos}', machining.lobe_figures, cfg, out_dir, pos,
                             _of(g.lobes, pos)))
    return g


def _of(table: Mapping[Pair, Delayed], position: str) -> dict[str, Delayed]:
    """The entries of one position, by scenario."""
    return {scn: value for (pos, scn), value in table.items() if pos == position}


@dataclass
class Progress(Callback):
    """
    One line per finished stage (``say``), counted; start and end of every stage.

    dask calls these methods in the thread that called :func:`compute`.
    """

    stage_of: dict[str, str]
    say: Callable[[str], None]
    started: dict[str, float] = field(default_factory=dict)
    finished: dict[str, float] = field(default_factory=dict)
    total: int = 0
    rank: dict[Any, tuple[float, int]] = field(default_factory=dict)

    def _start_state(self, dsk: Mapping[str, Any], state: Any) -> None:
        self.total = sum(key in self.stage_of for key in dsk)
        self.rank = critical_path(dsk, state['dependents'], self.stage_of)
        self._reorder(state)

    def _reorder(self, state: Any) -> None:
        """
        The ready stages by rank: dask's local scheduler starts the last of its ready list.

        dask orders the ready tasks depth first, which suits memory, not two threads and
        tasks from 0.3 to 30 s long. The rank is the longest chain of :data:`STAGE_COST`
        from a task to the end of the study (critical-path list scheduling); ties keep
        dask's order.
        """
        state['ready'].sort(key=lambda key: self.rank.get(key, (0.0, 0)))

    def _pretask(self, key: str, dsk: Any, state: Any) -> None:
        self.started[key] = time.perf_counter()

    def _posttask(self, key: str, result: Any, dsk: Any, state: Any, worker_id: Any) -> None:
        self.finished[key] = time.perf_counter()
        self._reorder(state)
        if key in self.stage_of:
            done = sum(k in self.stage_of for k in self.finished)
            line = result.describe() if hasattr(result, 'describe') else key
            if not (isinstance(result, Figures) and not result.paths):
                self.say(f'({done}/{self.total}) {line}')

    def timeline(self, origin: float) -> list[dict[str, Any]]:
        """Every stage's task with its start and end [s after ``origin``], in start order."""
        keys = sorted((k for k in self.finished if k in self.stage_of),
                      key=self.started.__getitem__)
        return [{'stage': self.stage_of[k], 'task': k, 'start_s': self.started[k] - origin,
                 'end_s': self.finished[k] - origin} for k in keys]

    def busy_share(self, jobs: int) -> float:
        """Summed busy time of the stages over ``jobs`` times first start to last end."""
        spans = self.timings()
        if not spans:
            return math.nan
        start = min(self.started[k] for k in self.finished if k in self.stage_of)
        end = max(self.finished[k] for k in self.finished if k in self.stage_of)
        return sum(busy for _, busy, _ in spans.values()) / (jobs * (end - start))

    def timings(self) -> dict[str, tuple[float, float, int]]:
        """Stage -> (first start to last end, summed busy time, count) [s]."""
        spans: dict[str, list[float]] = {}
        for key, end in self.finished.items():
            if key not in self.stage_of:
                continue
            start = self.started[key]
            span = spans.setdefault(self.stage_of[key], [start, end, 0.0, 0])
            span[0], span[1] = min(span[0], start), max(span[1], end)
            span[2] += end - start
            span[3] += 1
        return {k: (v[1] - v[0], v[2], int(v[3])) for k, v in spans.items()}


def critical_path(dsk: Mapping[Any, Any], dependents: Mapping[Any, Any],
                  stage_of: Mapping[str, str]) -> dict[Any, tuple[float, int]]:
    """
    Key -> (longest chain of stage costs from it to the end [s], -its place in dask's order).

    A stage costs :data:`STAGE_COST` of its stage (1 s for one not listed); dask's own tasks
    (collecting results) cost nothing.
    """
    from dask.order import order
    place = order(dsk)
    rank: dict[Any, float] = {}

    def chain(key: Any) -> float:
        if key not in rank:
            stage = stage_of.get(key) if isinstance(key, str) else None
            own = 0.0 if stage is None else STAGE_COST.get(stage, 1.0)
            rank[key] = own + max((chain(d) for d in dependents.get(key, ())), default=0.0)
        return rank[key]
    for key in dsk:
        chain(key)
    return {key: (rank[key], -place[key]) for key in dsk}


def compute(outputs: Any, stage_of: dict[str, str], jobs: int,
            say: Callable[[str], None]) -> tuple[Any, Progress]:
    """
    Compute ``outputs`` (a structure of stages) on ``jobs`` threads; the same structure back.

    Raises
    ------
    Exception
        The first error a stage raised (no further stage started; the running ones finished).
    Interrupted
        If a stop signal arrived.
    """
    progress = Progress(stage_of, say)
    values: Any = None
    with ThreadPoolExecutor(max(1, jobs), thread_name_prefix='study') as pool, progress:
        try:
            (values,) = dask_compute(outputs, scheduler='threads', pool=pool)
        except BaseException:      # noqa: B902 (re-raised once the running stages end)
            if not shutdown.requested():
                shutdown.request(signal.SIGTERM)    # stops the running testbed runs
                raise
        # leaving the pool waits for the stages still running
    if shutdown.requested():
        raise Interrupted(shutdown.signal_name(), shutdown.exit_code())
    return values, progress


def run_study(res: StudyResults, jobs: int, say: Callable[[str], None], runs: bool = True,
              lane: bool = False, fe_model: Path | None = None) -> Progress:
    """Every stage of the study, ``jobs`` at a time; ``res`` filled in the study's order."""
    g = study_graph(res.cfg, res.out_dir, res.freq, runs, lane, fe_model)
    values, progress = compute(g.outputs(), g.graph.stage_of, jobs, say)
    for name, value in values.items():
        setattr(res, name, value)
    return progress
