"""
The plant's truncation check at start-up, over ROS: the sources' linear models, then the check.

Every force source publishes the linear model of its law once, on
``/pentapod/controller_models/<source>`` (:func:`pentapod_sim.interface.controller_model_topic`;
std_msgs/String, reliable, transient local, depth 1, so a plant started later still gets it):
the JSON text of :meth:`pentapod_sim.sim.controllers.DiscreteController.to_json`,
``no feedback`` for a source that reads no plant output (the exciter), or ``no linear model:
<reason>`` (a PMA with limits). :class:`pentapod_sim.nodes.lockstep_source.LockstepSource`
publishes it for every testbed source (:func:`publish_model`); a user's controller may publish
one the same way.

The plant (:mod:`pentapod_sim.nodes.plant_node`) collects the models once its sources appeared,
for at most :data:`MODEL_TIMEOUT` s, and closes the sampled loop with them
(:func:`pentapod_sim.sim.stability.check_loop`) on its own model and on the check model of its
position: every FE mode below ``max(loop_check_f_min, 2 sample_rate)``, built once and cached in
``model_cache_dir`` (the cache the study's check models use, so neither pays twice). A plant
model without a position (a synthetic or modal-data model) is checked on itself only. The radii
of a loop are kept in ``model_cache_dir`` too (:func:`loop_result`), so a run of the same loop
again reads them instead of solving the eigenvalue problem (seconds for a 5 kHz scenario). It logs
the margins and names the sources it could not check; with ``loop_check`` = ``refuse`` a loop
that is not stable ends the run with a RunError naming the spectral radius, with ``warn`` it
logs a loud warning and runs, ``off`` skips the check.
"""
from __future__ import annotations

from contextlib import contextmanager
import dataclasses
import hashlib
import json
import logging
from pathlib import Path
import time
from typing import Callable, Mapping, Sequence

import scipy.linalg as sla
from std_msgs.msg import String

from pentapod_sim import shutdown
from pentapod_sim.errors import ConfigError, RunError
from pentapod_sim.interface import controller_model_topic, NO_FEEDBACK, NO_LINEAR_MODEL
from pentapod_sim.nodes.common import qos, spin_until
from pentapod_sim.plant.check_model import (
    check_cache_file,
    check_f_max,
    CheckStopped,
    load_or_build_check_model,
)
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.sim.controllers import DiscreteController
from pentapod_sim.sim.stability import apply_policy, check_loop, LoopCheck, UnstableLoopError

#: Wall time [s] the plant waits for the models of its sources after they appeared.
MODEL_TIMEOUT = 2.0
MODEL_QOS = qos('model')


# -- sources -------------------------------------------------------------------------------
def parallel(controllers: Sequence[DiscreteController]) -> DiscreteController:
    """The laws of one node side by side: one controller, ports and states concatenated."""
    return DiscreteController(
        [p for k in controllers for p in k.sensor_ports],
        [p for k in controllers for p in k.actuator_ports],
        *(sla.block_diag(*(getattr(k, m) for k in controllers)) for m in 'abcd'))


def model_text(linear_model: Callable[[], DiscreteController], feedback: bool = True) -> str:
    """
    The message text of a source's law (see the module docstring).

    Parameters
    ----------
    linear_model : callable
        Returns the law's DiscreteController; a ConfigError says why it has none.
    feedback : bool
        False for a source that reads no plant output (``no feedback``).
    """
    if not feedback:
        return NO_FEEDBACK
    try:
        return linear_model().to_json()
    except ConfigError as err:
        return f'{NO_LINEAR_MODEL}: {err}'


def publish_model(node, source_name: str, text: str):
    """Publish ``text`` once on the source's latched model topic; return the publisher."""
    pub = node.create_publisher(String, controller_model_topic(source_name), MODEL_QOS)
    pub.publish(String(data=text))
    return pub


# -- plant ---------------------------------------------------------------------------------
def sort_models(texts: Mapping[str, str | None], plant: PlantModel
                ) -> tuple[dict[str, DiscreteController], list[str], dict[str, str]]:
    """
    Sort the sources' model texts into linear models, open-loop sources and unchecked ones.

    Parameters
    ----------
    texts : mapping
        Source name -> message text, None for a source that sent none.
    plant : PlantModel
        The plant whose ports a model must use.

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
    """The plant's latched subscriptions to its sources' model topics."""

    def __init__(self, node, sources: Sequence[str]):
        self.sources = list(sources)
        self.texts: dict[str, str] = {}
        self.subs = [node.create_subscription(
            String, controller_model_topic(s),
            lambda msg, s=s: self.texts.__setitem__(s, msg.data), MODEL_QOS)
            for s in self.sources]

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


def check_plant_model(node) -> tuple[PlantModel | None, str]:
    """The check model of the plant's position (built once, cached) and its file name."""
    position = node.model.meta.get('position') or ''
    log = node.get_logger()
    if not position:
        log.info('truncation check on the plant model only: it has no FE position')
        return None, ''
    f_max = check_f_max(node.params.sample_rate, node.params.loop_check_f_min)
    cached = check_cache_file(position, f_max, node.params.model_cache_dir)
    if not cached.exists():
        log.info(f'truncation check: building the check model of {position} (FE modes below '
                 f'{f_max:g} Hz) once; later runs load it from {node.params.model_cache_dir}')
    try:
        with forwarded_logs(log):
            check, origin = load_or_build_check_model(position, f_max,
                                                      node.params.model_cache_dir,
                                                      stop=shutdown.requested)
    except CheckStopped:        # check_at_start sees the stop request and skips the check
        return None, ''
    log.info(f'check model {origin}: {check.n_modes} modes')
    return check, cached.name


def loop_result(node, models: Mapping[str, DiscreteController], check: PlantModel | None,
                check_name: str, label: str) -> tuple[LoopCheck | None, Path | None]:
    """
    The radii of the loop on plant and check model, computed once per loop and kept.

    With a check model the result is stored as ``loop_check_<key>.json`` in
    ``model_cache_dir``, keyed by the plant's content hash, the check model's file name, dt and
    the models, so a scenario run again (or the study's runs of one scenario) does not solve the
    same eigenvalue problem twice (a plant checked on itself is quick and kept nowhere). Returns
    the result and the file it was read from (None: computed now); no result if a stop was
    requested meanwhile (:func:`pentapod_sim.shutdown.unless_requested`).
    """
    doc = [node.model.content_hash(), check_name, repr(node.dt), label,
           [m.to_json() for m in models.values()]]
    key = hashlib.sha256(json.dumps(doc).encode()).hexdigest()[:16]
    path = (None if check is None
            else Path(node.params.model_cache_dir) / f'loop_check_{key}.json')
    if path is not None and path.is_file():
        try:
            return LoopCheck(**json.loads(path.read_text())), path
        except (OSError, ValueError, TypeError):
            pass                                    # unreadable: computed and written again
    quiet = logging.getLogger('pentapod_sim.sim.stability')
    was, quiet.disabled = quiet.disabled, True      # the policy is applied (and logged) here
    try:    # seconds of LAPACK for a check model: a stop signal must not wait for them
        result = shutdown.unless_requested(lambda: check_loop(
            node.model, check, list(models.values()), node.dt, 'warn', label,
            lambda msg: shutdown.requested() or node.get_logger().info(msg)))
    finally:
        quiet.disabled = was
    if result is None:
        return None, None
    try:
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(dataclasses.asdict(result)))
    except OSError as err:
        node.get_logger().warning(f'truncation check result not kept: {err}')
    return result, None


def check_at_start(node, executor) -> LoopCheck | None:
    """
    The plant node's truncation check before step 0 (parameter ``loop_check``).

    A stop request (:mod:`pentapod_sim.shutdown`) that comes while the sources' models are
    awaited, the check model is built or the eigenvalue problem is solved skips the rest of
    the check (None).

    Raises
    ------
    RunError
        With ``loop_check`` = ``refuse`` if the loop is unstable on the plant or stable only
        thanks to truncation; the message gives the spectral radii.
    """
    policy, log = node.params.loop_check, node.get_logger()
    if policy == 'off':
        log.info('truncation check off (loop_check = off)')
        return None
    texts = node.loop_models.wait(executor)
    if shutdown.requested():    # stopped while waiting: no check model, no eigenvalues
        return None
    models, open_loop, unchecked = sort_models(texts, node.model)
    missing = ''.join(f'; unchecked source {s!r}: {why}' for s, why in unchecked.items())
    if unchecked:
        log.warning(f'truncation check: source(s) {", ".join(unchecked)} gave no linear model '
                    f'and are left out of the check (unchecked){missing}')
    if not models:
        log.info('truncation check: no source with a linear model closes a loop (open-loop '
                 f'sources: {open_loop or "none"}); nothing to check')
        return None
    start = time.monotonic()
    check, check_name = check_plant_model(node)
    if shutdown.requested():    # stopped while the check model was built: skip the check, so
        return None             # the plant ends before the runner's SIGKILL (5 s after SIGINT)
    result, kept = loop_result(node, models, check, check_name, f'loop of plant and '
                               f'{", ".join(models)}')
    if result is None:          # stopped during the eigenvalue problem
        return None
    if kept is not None:
        log.info(f'truncation check: result of an earlier run read from {kept}')
    try:
        apply_policy(result, 'refuse')
    except UnstableLoopError as err:
        if policy == 'refuse':
            raise RunError(f'truncation check (loop_check = refuse): {err}{missing}') from None
        log.warning(f'!!! truncation check (loop_check = warn): {err}{missing} -- results '
                    'of this run are not trustworthy !!!')
        return None
    log.info(f'truncation check in {time.monotonic() - start:.1f} s: {result.summary()}'
             + (f' (open-loop sources: {", ".join(open_loop)})' if open_loop else ''))
    return result
