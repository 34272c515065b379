"""
The control laws of a scenario, offline: what its source nodes close around the plant.

Every source node's parameter class says which laws it runs
(:meth:`pentapod_sim.parameters.SourceParams.loop_laws`, built with the node's own functions
and defaults): the damper and PMA nodes their laws, the exciter and the cutting node none (they
close no control loop). The node kinds, and so the classes, come from the registry
(:data:`pentapod_sim.registry.NODES`), which is how this package reaches the laws of
``pentapod_damper`` without importing it. A node whose class does not say (a user's controller
without ``loop_laws``) is refused, naming it: an offline model without its law would be wrong.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import sample_time
from pentapod_sim.plant.drives import drive_set, DriveSet, with_drives
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.registry import SOURCE
from pentapod_sim.scenario.files import read_scenario, Scenario


def scenario_dt(scenario: str | Path | Scenario) -> float:
    """Sample time [s] of a scenario: its plant's ``sample_rate``."""
    return sample_time(read_scenario(scenario).plant.params.sample_rate)


def scenario_drives(scenario: str | Path | Scenario) -> DriveSet | None:
    """The feed drives a scenario's plant node steps (its ``drives``, ``drive_struts``)."""
    params = read_scenario(scenario).plant.params
    return drive_set(params.drives, params.drive_struts)


def scenario_plant(scenario: str | Path | Scenario, plant: PlantModel) -> Any:
    """
    ``plant`` as the scenario's plant node steps it (the feed drives' rotors too, if any).

    With the plant parameter ``drives`` set: :class:`pentapod_sim.plant.drives.DrivenPlant`
    of ``plant`` and those drives (:func:`scenario_drives`); otherwise ``plant`` itself.
    """
    return with_drives(plant, scenario_drives(scenario))


def scenario_loop_laws(scenario: str | Path | Scenario, dt: float | None = None) -> list[Any]:
    """
    Every control law of a scenario's source nodes, in file order.

    Parameters
    ----------
    scenario : str, Path or Scenario
        A shipped scenario's name, a scenario file or a parsed scenario.
    dt : float, optional
        Sample time [s] the laws are built for (default: the scenario's, :func:`scenario_dt`).

    Raises
    ------
    ConfigError
        If the file is bad, or a source node's class does not say which laws it runs.
    """
    parsed = read_scenario(scenario)
    step = scenario_dt(parsed) if dt is None else dt
    laws: list[Any] = []
    for node in parsed.nodes:
        if node.role != SOURCE:
            continue
        factory = getattr(node.params, 'loop_laws', None)
        if factory is None:
            raise ConfigError(f'{parsed.path}: node {node.name!r} ({node.node_class}) does not '
                              'say which laws it runs (its parameter class has no loop_laws): '
                              'it cannot be modelled offline')
        try:
            laws += factory(step)
        except ConfigError as err:
            raise ConfigError(f'{parsed.path}: node {node.name!r}: {err}') from None
    return laws
