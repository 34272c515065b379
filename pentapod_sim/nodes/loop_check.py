"""
The plant's truncation check at start-up, over ROS: the sources' linear models, then the check.

Every force source publishes the linear model of its law once on its latched model topic
(:mod:`pentapod_sim.nodes.source_model`, which has the message format; the sources' side imports
nothing of this module and so no FE code).

The plant (:mod:`pentapod_sim.nodes.plant_node`) collects the models once its sources appeared,
for at most :data:`MODEL_TIMEOUT` s, and closes the sampled loop with them
(:func:`pentapod_sim.sim.stability.check_loop`) on its own model and on the check model of its
position: every FE mode below ``max(loop_check_f_min, 2 sample_rate)``, built once and cached in
``model_cache_dir`` (the cache the study's check models use, so neither pays twice). A plant
model without a position (a synthetic or modal-data model) is checked on itself only. The
radii of a loop are kept in ``model_cache_dir`` too (:meth:`TruncationCheck.result`), so a run
of the same loop again reads them instead of solving the eigenvalue problem (seconds for a 5 kHz
scenario). It logs the margins and names the sources it could not check; with ``loop_check`` =
``refuse`` a loop that is not stable ends the run with a RunError naming the spectral radius,
with ``warn`` it logs a loud warning and runs, ``off`` skips the check (:class:`TruncationCheck`).

A source that publishes a new model during the run (a damper whose gain was set) is checked
again (:meth:`TruncationCheck.during_run`), in a thread while the run goes on: the plant logs
the step at which the model arrived and the result, and ``refuse`` then ends the run, ``warn``
logs the loud warning.
"""
from __future__ import annotations

from contextlib import contextmanager
import dataclasses
import hashlib
import json
import logging
from pathlib import Path
import threading
import time
from typing import Any, Callable, Mapping, Sequence

from std_msgs.msg import String

from pentapod_sim import shutdown
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.interface import controller_model_topic, NO_FEEDBACK, NO_LINEAR_MODEL
from pentapod_sim.nodes.common import spin_until
from pentapod_sim.nodes.source_model import MODEL_QOS
from pentapod_sim.plant.check_model import (
    check_cache_file,
    check_f_max,
    CheckStopped,
    load_or_build_check_model,
)
from pentapod_sim.plant.drives import DrivenPlant, DriveSet, with_drives
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.stability import apply_policy, check_loop, LoopCheck, UnstableLoopError

#: Wall time [s] the plant waits for the models of its sources after they appeared.
MODEL_TIMEOUT = 2.0


def sort_models(texts: Mapping[str, str | None], plant: PlantModel | DrivenPlant
                ) -> tuple[dict[str, DiscreteController], list[str], dict[str, str]]:
    """
    Sort the sources' model texts into linear models, open-loop sources and unchecked ones.

    Parameters
    ----------
    texts : mapping
        Source name -> message text, None for a source that sent none.
    plant : PlantModel or DrivenPlant
        The plant whose ports a model must use (with the drives' motor ports if it has them).

    Returns
    -------
    models : dict
        Source -> its controller.
    open_loop : list of str
        Sources that read no plant output.
    unchecked : dict
        Source -> why its law is left out of the check.
    """
    models, open_loop, unchecked = {}, [], {}
    for source, text in texts.items():
        if text is None:
            unchecked[source] = f'published no model within {MODEL_TIMEOUT:g} s'
        elif text == NO_FEEDBACK:
            open_loop.append(source)
        elif text.startswith(NO_LINEAR_MODEL):
            unchecked[source] = text
        else:
            try:
                ctrl = DiscreteController.from_json(text)
            except ConfigError as err:
                unchecked[source] = str(err)
                continue
            strays = ([p for p in ctrl.sensor_ports if p not in plant.output_names]
                      + [p for p in ctrl.actuator_ports if p not in plant.input_names])
            if strays:
                unchecked[source] = f'its model names port(s) the plant lacks: {strays}'
            else:
                models[source] = ctrl
    return models, open_loop, unchecked


class ModelCollector:
    """
    The plant's latched subscriptions to its sources' model topics.

    ``step`` gives the plant's current step; the step at which each source's latest model
    arrived is kept in ``arrived``.
    """

    def __init__(self, node, sources: Sequence[str], step: Callable[[], int] = lambda: 0):
        self.sources, self.step = list(sources), step
        self.texts: dict[str, str] = {}
        self.arrived: dict[str, int] = {}
        self.subs = [node.create_subscription(
            String, controller_model_topic(s), lambda msg, s=s: self.take(s, msg.data),
            MODEL_QOS) for s in self.sources]

    def take(self, source: str, text: str) -> None:
        """Keep a source's model text and the plant's step when it arrived."""
        if self.texts.get(source) != text:
            self.texts[source], self.arrived[source] = text, self.step()

    def wait(self, executor, timeout: float = MODEL_TIMEOUT) -> dict[str, str | None]:
        """Spin until every source's model is in or ``timeout`` [s]; source -> text or None."""
        spin_until(executor, lambda: shutdown.requested() or all(
            s in self.texts for s in self.sources), timeout)
        return {s: self.texts.get(s) for s in self.sources}


class _ToRosLogger(logging.Handler):
    """Pass Python log records (check-model build progress) on to a node's logger."""

    def __init__(self, logger):
        super().__init__(logging.INFO)
        self.ros = logger

    def emit(self, record: logging.LogRecord) -> None:
        log = self.ros.warning if record.levelno >= logging.WARNING else self.ros.info
        log(record.getMessage())


@contextmanager
def forwarded_logs(logger, name: str = 'pentapod_sim'):
    """Within the block, INFO and above of the Python logger ``name`` go to ``logger``."""
    py = logging.getLogger(name)
    handler, level = _ToRosLogger(logger), py.level
    py.addHandler(handler)
    py.setLevel(logging.INFO)
    try:
        yield
    finally:
        py.removeHandler(handler)
        py.setLevel(level)


class TruncationCheck:
    """
    The plant node's truncation check before step 0 (parameter ``loop_check``).

    Parameters
    ----------
    models : ModelCollector
        The plant's subscriptions to its sources' models (``wait(executor)`` gives the texts).
    plant : PlantModel
        The plant's model.
    dt : float
        The plant's exchange step [s].
    policy : str
        ``refuse``, ``warn`` or ``off`` (parameter ``loop_check``).
    sample_rate, f_min : float
        The exchange rate and ``loop_check_f_min`` [Hz]: the check model's band
        (:func:`pentapod_sim.plant.check_band.check_f_max`).
    cache_dir : str
        ``model_cache_dir``: check models and loop results are kept there.
    log : logger
        The node's logger.
    drives : DriveSet, optional
        The feed drives the plant steps (parameter ``drives``): plant and check model are
        checked with their rotors.
    """

    def __init__(self, models, plant: PlantModel, dt: float, policy: str, sample_rate: float,
                 f_min: float, cache_dir: str, log, drives: DriveSet | None = None):
        self.models, self.plant, self.dt, self.policy = models, plant, dt, policy
        self.drives = drives
        #: the ports the sources' models may use: the plant's, with the motors'
        self.ports: PlantModel | DrivenPlant = with_drives(plant, drives)
        self.sample_rate, self.f_min, self.cache_dir, self.log = sample_rate, f_min, cache_dir, log
        self.checked: dict[str, str | None] = {}     # the model texts the last check used
        self._check: tuple[PlantModel | None, str] | None = None    # (check model, name)
        self._worker: threading.Thread | None = None
        self._outcome: dict[str, Any] = {}

    def check_model(self) -> tuple[PlantModel | None, str]:
        """The check model of the plant's position (built once, cached) and its file name."""
        if self._check is None:
            check = self._load_check_model()
            if check[1] == 'stopped':       # not kept: a later call builds it again
                return None, ''
            self._check = check
        return self._check

    def _load_check_model(self) -> tuple[PlantModel | None, str]:
        position, log = self.plant.meta.get('position') or '', self.log
        if not position:
            log.info('truncation check on the plant model only: it has no FE position')
            return None, ''
        f_max = check_f_max(self.sample_rate, self.f_min)
        cached = check_cache_file(position, f_max, self.cache_dir)
        if not cached.exists():
            log.info(f'truncation check: building the check model of {position} (FE modes '
                     f'below {f_max:g} Hz) once; later runs load it from {self.cache_dir}')
        try:
            with forwarded_logs(log):
                check, origin = load_or_build_check_model(position, f_max, self.cache_dir,
                                                          stop=shutdown.requested)
        except CheckStopped:        # the caller sees the stop request and skips the check
            return None, 'stopped'
        log.info(f'check model {origin}: {check.n_modes} modes')
        return check, cached.name

    def result(self, models: Mapping[str, DiscreteController], check: PlantModel | None,
               check_name: str, label: str) -> tuple[LoopCheck | None, Path | None]:
        """
        The radii of the loop on plant and check model, computed once per loop and kept.

        With a check model the result is stored as ``loop_check_<key>.json`` in
        ``model_cache_dir``, keyed by the plant's content hash, the check model's file name, dt
        and the models, so a scenario run again (or the study's runs of one scenario) does not
        solve the same eigenvalue problem twice (a plant checked on itself is quick and kept
        nowhere). Returns the result and the file it was read from (None: computed now); no
        result if a stop was requested meanwhile (:func:`pentapod_sim.shutdown.unless_requested`).
        """
        doc = [self.plant.content_hash(), check_name, repr(self.dt), label,
               [m.to_json() for m in models.values()], repr(self.drives)]
        key = hashlib.sha256(json.dumps(doc).encode()).hexdigest()[:16]
        path = None if check is None else Path(self.cache_dir) / f'loop_check_{key}.json'
        if path is not None and path.is_file():
            try:
                return LoopCheck(**json.loads(path.read_text())), path
            except (OSError, ValueError, TypeError):
                pass                                # unreadable: computed and written again
        quiet = logging.getLogger('pentapod_sim.sim.stability')
        was, quiet.disabled = quiet.disabled, True  # the policy is applied (and logged) here
        try:    # seconds of LAPACK for a check model: a stop signal must not wait for them
            result = shutdown.unless_requested(lambda: check_loop(
                self.plant, check, list(models.values()), self.dt, 'warn', label,
                lambda msg: shutdown.requested() or self.log.info(msg), self.drives),
                name='truncation check')
        finally:
            quiet.disabled = was
        if result is None:
            return None, None
        try:
            if path is not None:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(json.dumps(dataclasses.asdict(result)))
        except OSError as err:
            self.log.warning(f'truncation check result not kept: {err}')
        return result, None

    def at_start(self, executor) -> LoopCheck | None:
        """
        Wait for the sources' models and check the loop they close with the plant.

        A stop request (:mod:`pentapod_sim.shutdown`) that comes while the sources' models are
        awaited, the check model is built or the eigenvalue problem is solved skips the rest
        of the check (None).

        Raises
        ------
        RunError
            With ``loop_check`` = ``refuse`` if the loop is unstable on the plant or stable
            only thanks to truncation; the message gives the spectral radii.
        """
        policy, log = self.policy, self.log
        if policy == 'off':
            log.info('truncation check off (loop_check = off)')
            return None
        texts = self.models.wait(executor)
        self.checked = dict(texts)
        if shutdown.requested():    # stopped while waiting: no check model, no eigenvalues
            return None
        models, open_loop, unchecked = sort_models(texts, self.ports)
        missing = ''.join(f'; unchecked source {s!r}: {why}' for s, why in unchecked.items())
        if unchecked:
            log.warning(f'truncation check: source(s) {", ".join(unchecked)} gave no linear '
                        f'model and are left out of the check (unchecked){missing}')
        if not models:
            log.info('truncation check: no source with a linear model closes a loop (open-loop '
                     f'sources: {open_loop or "none"}); nothing to check')
            return None
        start = time.monotonic()
        check, check_name = self.check_model()
        if shutdown.requested():    # stopped while the check model was built: skip the check,
            return None             # so the plant ends before the runner's SIGKILL
        result, kept = self.result(models, check, check_name,
                                   f'loop of plant and {", ".join(models)}')
        if result is None:          # stopped during the eigenvalue problem
            return None
        if kept is not None:
            log.info(f'truncation check: result of an earlier run read from {kept}')
        try:
            apply_policy(result, 'refuse')
        except UnstableLoopError as err:
            if policy == 'refuse':
                raise RunError(f'truncation check (loop_check = refuse): {err}{missing}'
                               ) from None
            log.warning(f'!!! truncation check (loop_check = warn): {err}{missing} -- results '
                        'of this run are not trustworthy !!!')
            return None
        log.info(f'truncation check in {time.monotonic() - start:.1f} s: {result.summary()}'
                 + (f' (open-loop sources: {", ".join(open_loop)})' if open_loop else ''))
        return result

    def during_run(self) -> None:
        """
        Check the loop again when a source published a new model during the run.

        Called with the plant's periodic graph checks: starts the check in a thread when a
        model text differs from those checked last, and applies the policy once it is done
        (logged with the step at which the model arrived).

        Raises
        ------
        RunError
            With ``loop_check`` = ``refuse``, once the new loop is found not stable.
        """
        if self.policy == 'off':
            return
        worker = self._worker
        if worker is not None:
            if not worker.is_alive():
                self._worker = None
                self._conclude(self._outcome)
            return
        texts = {s: self.models.texts.get(s) for s in self.models.sources}
        changed = [s for s in texts if texts[s] != self.checked.get(s)]
        if not changed:
            return
        self.checked = texts
        steps = {s: self.models.arrived.get(s, 0) for s in changed}
        self.log.info('truncation check again: new model of ' + ', '.join(
            f'{s} (arrived at step {k})' for s, k in steps.items()))
        self._outcome = outcome = {'steps': steps}

        def work() -> None:
            try:
                models, _, unchecked = sort_models(texts, self.ports)
                outcome['unchecked'] = unchecked
                if models:
                    check, name = self.check_model()
                    outcome['result'] = self.result(
                        models, check, name, f'loop of plant and {", ".join(models)}')[0]
            except Exception as err:       # noqa: BLE001 (reported by _conclude)
                outcome['error'] = err
        self._worker = threading.Thread(target=work, name='truncation check', daemon=True)
        self._worker.start()

    def _conclude(self, outcome: Mapping[str, Any]) -> None:
        """Log or refuse the result of a check during the run."""
        when = ', '.join(f'{s} from step {k}' for s, k in outcome['steps'].items())
        if 'error' in outcome:
            raise RunError(f'truncation check of the new model of {when} failed: '
                           f'{outcome["error"]}')
        missing = ''.join(f'; unchecked source {s!r}: {why}'
                          for s, why in outcome.get('unchecked', {}).items())
        result = outcome.get('result')
        if result is None:
            self.log.warning(f'truncation check of the new model of {when}: no linear model '
                             f'closes a loop{missing}')
            return
        try:
            apply_policy(result, 'refuse')
        except UnstableLoopError as err:
            if self.policy == 'refuse':
                raise RunError(f'truncation check (loop_check = refuse) of the new model of '
                               f'{when}: {err}{missing}') from None
            self.log.warning(f'!!! truncation check (loop_check = warn) of the new model of '
                             f'{when}: {err}{missing} -- results of this run from then on are '
                             'not trustworthy !!!')
            return
        self.log.info(f'truncation check of the new model of {when}: {result.summary()}')
