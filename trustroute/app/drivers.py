"""The synthetic driver of an episode, a population's drawn driver type, and episode ids.

Every simulated episode's driver is built here (the API, `trustroute run`, the gymnasium
environment, a study's episodes, the live study's scripted participant), so its Generator, report
accuracy and initial trust are passed the same way everywhere.
"""

from __future__ import annotations

import numpy as np

from trustroute.participants.driver_model import DEFAULT_REPORT_ACCURACY, DriverModel
from trustroute.participants.driver_population import DriverPopulation
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
