"""
Robustness of the loop: the controller's own FRF from its run, checked on the check model.

The robustness run drives every port the controller answers (and the collocated inputs of the
sensors it reads) with independent white noise. From the bag: the sensors it reads ``y`` (the
ports of its published model; else ``--sensors``; else the velocities collocated with its
ports, the assumption of a collocated damper, which the report states) and its answers ``u``
(summed per port over its sources). Their H1 estimate is the controller's FRF ``K = u / y`` with
its multiple coherence (:func:`pentapod_sim.analysis.frf.mimo.mimo_frf`). The generalised
Nyquist criterion (:func:`pentapod_sim.sim.nyquist.nyquist_check`) closes ``K`` with the
reduced plant and with the check model (every FE mode below the check frequency), as run and
with one more sample of delay.

A controller that published its linear model also gets the exact check: the spectral radius of
the sampled loop on both models (:func:`pentapod_sim.sim.stability.check_loop`), with and
without the extra sample, and the same Nyquist check with the model's FRF instead of the
identified one, so that the two margins can be compared.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pentapod_sim.analysis.bag.reader import Bag, open_bag
from pentapod_sim.analysis.bag.run_record import controller_models
from pentapod_sim.analysis.frf.mimo import mimo_frf, MimoFrf
from pentapod_sim.errors import BagError, ConfigError
from pentapod_sim.interface import force_topic, NO_FEEDBACK, port_location
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.plant.ports import collocated_output
from pentapod_sim.sim.controllers import DiscreteController, parallel, with_delay
from pentapod_sim.sim.nyquist import controller_frf, nyquist_check, NyquistCheck
from pentapod_sim.sim.stability import check_loop, LoopCheck

#: Loops of the check: (plant name, samples of extra delay).
LOOPS = (('plant', 0), ('check', 0), ('plant', 1), ('check', 1))


def published_models(bag: Bag, sources: Sequence[str]) -> list[DiscreteController] | None:
    """The sources' linear models from the bag; None if one of them published none."""
    texts = controller_models(bag)
    models = []
    for source in sources:
        text = texts.get(source)
        if text is None or text == NO_FEEDBACK:
            return None
        try:
            models.append(DiscreteController.from_json(text))
        except ConfigError:               # "no linear model: ..."
            return None
    return models


def answered_ports(bag: Bag, sources: Sequence[str]) -> tuple[str, ...]:
    """Input ports named in the sources' recorded answers, in first-seen order."""
    ports: list[str] = []
    for source in sources:
        topic = force_topic(source)
        if topic not in bag.topics or not bag.topic(topic).count:
            raise BagError(f'{bag.path}: the controller answered nothing on {topic}')
        ports += [f.split('.', 1)[1] for f in bag.fields(topic) if f.startswith('effort.')]
    return tuple(dict.fromkeys(ports))


def _steps(bag: Bag, spec: str, dt: float) -> dict[int, float]:
    series = bag.series(spec)
    steps = np.rint(series.time_ns / (dt * 1e9)).astype(np.int64)
    return dict(zip(steps.tolist(), np.asarray(series.values, dtype=float).tolist()))


def loop_signals(bag: Bag, sources: Sequence[str], ports: Sequence[str],
                 sensors: Sequence[str], dt: float
                 ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(y, u): the sensors and the summed answers per port on the steps all of them have."""
    columns = []
    for port in sensors:
        topic, joint, what = port_location(port)
        columns.append(_steps(bag, f'{topic}.{what}.{joint}', dt))
    answers = []
    for port in ports:
        total: dict[int, float] = {}
        for source in sources:
            spec = f'{force_topic(source)}.effort.{port}'
            try:
                part = _steps(bag, spec, dt)
            except BagError:
                continue                   # this source does not drive the port
            total = part if not total else {k: total[k] + v for k, v in part.items()
                                            if k in total}
        answers.append(total)
    common = sorted(set.intersection(*(set(c) for c in columns + answers)))
    if len(common) < 64:
        raise BagError(f'{bag.path}: sensors and answers share only {len(common)} steps')
    y = np.array([[c[k] for c in columns] for k in common])
    u = np.array([[a[k] for a in answers] for k in common])
    return y, u


@dataclass
class Robustness:
    """The identified controller and the checks of its loop."""

    sensors: tuple[str, ...]
    ports: tuple[str, ...]
    sensors_assumed: bool
    frf: MimoFrf
    coherence_min: float
    black_box: dict[tuple[str, int], NyquistCheck]
    model: DiscreteController | None = None
    exact: dict[tuple[str, int], LoopCheck] = field(default_factory=dict)
    model_nyquist: dict[tuple[str, int], NyquistCheck] = field(default_factory=dict)

    @property
    def has_check(self) -> bool:
        """The loop was closed on a check model too."""
        return any(k[0] == 'check' for k in self.black_box)


def sensors_of(models: list[DiscreteController] | None, given: Sequence[str],
               ports: Sequence[str]) -> tuple[tuple[str, ...], bool]:
    """The sensor ports and whether they were assumed (collocated velocities)."""
    if models:
        return tuple(dict.fromkeys(p for m in models for p in m.sensor_ports)), False
    if given:
        return tuple(given), False
    return tuple(collocated_output(p) for p in ports), True


def assess(bag_path: Path, sources: Sequence[str], given_sensors: Sequence[str],
           plant: PlantModel, check: PlantModel | None, dt: float,
           nperseg: int, label: str) -> Robustness:
    """Identify the controller from its robustness run and check its loop (module docstring)."""
    bag = open_bag(bag_path)
    ports = answered_ports(bag, sources)
    models = published_models(bag, sources)
    sensors, assumed = sensors_of(models, given_sensors, ports)
    y, u = loop_signals(bag, sources, ports, sensors, dt)
    frf = mimo_frf([(y, u)], dt, min(nperseg, y.shape[0]), sensors, ports)
    finite = np.isfinite(frf.coherence)
    coherence = float(np.min(frf.coherence[finite])) if finite.any() else float('nan')
    if not np.all(frf.identifiable):
        raise BagError(f'{bag_path}: the controller reads {len(sensors)} sensors that the run '
                       'did not excite independently; give the sensors it reads (--sensors)')
    plants = {'plant': plant}
    if check is not None:
        plants['check'] = check.select(plant.input_names, plant.output_names)

    def identified(freq: npt.NDArray[np.float64]) -> npt.NDArray[np.complex128]:
        return frf.at(freq)
    result = Robustness(sensors, ports, assumed, frf, coherence, {})
    for name, delay in LOOPS:
        if name in plants:
            result.black_box[(name, delay)] = nyquist_check(
                plants[name], sensors, ports, identified, dt, delay,
                f'{label}, identified, on the {name}')
    if models:
        model = _on_ports(parallel(models), sensors, ports)
        result.model = model
        for name, delay in LOOPS:
            if name not in plants:
                continue
            result.model_nyquist[(name, delay)] = nyquist_check(
                plants[name], sensors, ports, controller_frf(model, dt), dt, delay,
                f'{label}, model, on the {name}')
            result.exact[(name, delay)] = check_loop(
                plant, plants[name] if name == 'check' else None, [with_delay(model, delay)],
                dt, policy='warn', label=f'{label} (+{delay} sample)')
    return result


def _on_ports(model: DiscreteController, sensors: Sequence[str],
              ports: Sequence[str]) -> DiscreteController:
    """The model with its inputs in ``sensors`` order and outputs summed onto ``ports``."""
    s_in = np.array([[1.0 if a == b else 0.0 for b in sensors] for a in model.sensor_ports])
    s_out = np.array([[1.0 if a == b else 0.0 for a in model.actuator_ports] for b in ports])
    return DiscreteController(sensors, ports, model.a, model.b @ s_in, s_out @ model.c,
                              s_out @ model.d @ s_in)
