"""The synthetic driver of an episode, a population's drawn driver type, episode ids, and drivers
simulated on given roads (the posterior-predictive check's draws).

Every simulated episode's driver is built here (the API, `trustroute run`, the gymnasium
environment, a study's episodes, the live study's scripted participant), so its Generator, report
accuracy and initial trust are passed the same way everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.participants.driver_model import DEFAULT_REPORT_ACCURACY, DriverModel, driver_tables
from trustroute.participants.driver_population import DriverPopulation
from trustroute.participants.driver_step import draw_initial_trust, draw_reports, draw_step
from trustroute.participants.synthetic_driver import SyntheticDriver


def synthetic_driver(model: DriverModel, rng: np.random.Generator, *,
                     report_accuracy: float = DEFAULT_REPORT_ACCURACY,
                     initial_trust: int | None = None) -> SyntheticDriver:
    """A synthetic driver of `model` drawing from `rng` (initial trust drawn unless given)."""
    return SyntheticDriver(model, rng, report_accuracy=report_accuracy, initial_trust=initial_trust)


def draw_type(population: DriverPopulation, rng: np.random.Generator) -> tuple[str, DriverModel]:
    """A driver type drawn from the population's weights (one draw of `rng`): its name and model."""
    k = int(rng.choice(population.n_types, p=population.weights))
    return population.names[k], population.types[k].model


def episode_id(spec_name: str, policy_name: str, seed: int) -> str:
    """The id of a single episode (the API's and `trustroute run`'s): spec, policy and seed."""
    return f"{spec_name}-{policy_name}-s{seed}"


def gym_episode_id(spec_name: str, count: int) -> str:
    """The id of the gymnasium environment's `count`-th episode."""
    return f"gym-{spec_name}-{count:06d}"


@dataclass(frozen=True)
class Simulated:
    """Drivers simulated on given roads: takeover and performance (1 = fail) [n, S] (roads 1..S,
    False past an episode's end), reported trust levels [n, S+1] (column 0: the start road; past
    an episode's end the last report is repeated)."""

    takeover: np.ndarray
    failed: np.ndarray
    report: np.ndarray


def simulate(
    model: DriverModel,
    incident: np.ndarray,
    mask: np.ndarray,
    accuracy: float,
    replicates: int,
    rng: np.random.Generator,
    incident_types: tuple[str, ...] | None = None,
) -> Simulated:
    """`replicates` drivers of `model` per row of the given roads (incident indices into
    `incident_types`, default the model's own [n, S]; mask [n, S]), rows in order n*R."""
    incident = np.repeat(incident, replicates, axis=0)
    mask = np.repeat(mask, replicates, axis=0)
    n: int
    steps: int
    n, steps = incident.shape
    tables = driver_tables([model], incident_types)
    levels = np.asarray(model.trust_levels)
    kind = np.zeros(n, dtype=np.int64)
    theta = draw_initial_trust(tables, kind, rng)
    takeover = np.zeros((n, steps), dtype=bool)
    failed = np.zeros((n, steps), dtype=bool)
    report = np.zeros((n, steps + 1), dtype=np.int64)
    report[:, 0] = levels[draw_reports(theta, accuracy, model.n_trust, rng)]
    for t in range(steps):
        live = np.flatnonzero(mask[:, t])
        h, e, theta[live] = draw_step(tables, kind[live], incident[live, t], theta[live], rng)
        takeover[live, t] = h.astype(bool)
        failed[live, t] = e.astype(bool)
        report[:, t + 1] = report[:, t]
        report[live, t + 1] = levels[draw_reports(theta[live], accuracy, model.n_trust, rng)]
    return Simulated(takeover=takeover, failed=failed, report=report)
