"""The episodes of a study: who drives which (spec, condition) in which position, with which seed.

Cells are the (spec, condition) pairs in config order (φ1-aware, φ1-free, φ2-aware, φ2-free for
the paper); participant p drives them in the order of row p of the Williams design
(harness/study/latin_square.py). Every random quantity is derived with numpy's SeedSequence
from the study seed and fixed keys, never from the order in which episodes run or complete:

- participant p's driver model: `sample_population` with SeedSequence(seed, spawn_key=(2,)),
  all participants at once (nominal for every participant when there is no [population]);
- with a `[drivers] population`, participant p's true type: one uniform draw of
  SeedSequence(seed, spawn_key=(3, p)) against the types' cumulative weights (so p's type does not
  depend on the number of participants); p's model is its type's model, or with a [population]
  one draw of `sample_individual` around it from the spawn_key=(2,) stream, participants in order;
- episode (p, spec s, condition c): SeedSequence(seed, spawn_key=(1, p, s, c)); its first
  32-bit word seeds the simulator (SUMO), the sequence itself seeds the driver's Generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.core.errors import InputError
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.latin_square import participant_order
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import load_driver_population
from trustroute.participants.population import (
    population_config_from_dict,
    sample_individual,
    sample_population,
)

EPISODE_KEY = 1
POPULATION_KEY = 2
TYPE_KEY = 3


@dataclass(frozen=True)
class EpisodeTask:
    """One planned episode; picklable, small (the driver model travels only if it is not nominal)."""

    episode_id: str
    participant: int
    position: int  # 0-based place in the participant's order
    spec: str  # spec name (file stem)
    spec_index: int
    condition: str  # condition label
    condition_index: int
    seed: int  # simulator seed (31 bits: SUMO takes a signed int)
    driver_entropy: tuple[int, ...]  # (study seed, spawn key...) of the driver's SeedSequence

    def driver_rng(self) -> np.random.Generator:
        seed, *spawn_key = self.driver_entropy
        return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=tuple(spawn_key)))


def episode_id(participant: int, spec: str, condition: str) -> str:
    return f"p{participant:05d}-{spec}-{condition}"


def episode_seed_sequence(
    study_seed: int, participant: int, spec_index: int, condition_index: int
) -> np.random.SeedSequence:
    return np.random.SeedSequence(
        study_seed, spawn_key=(EPISODE_KEY, participant, spec_index, condition_index)
    )


def plan_episodes(config: StudyConfig) -> list[EpisodeTask]:
    """Every episode of the study, in (participant, position) order."""
    cells = [(s, c) for s in range(len(config.specs)) for c in range(len(config.conditions))]
    spec_names, condition_names = config.spec_names, config.condition_names
    tasks = []
    for p in range(config.participants):
        for position, cell in enumerate(participant_order(p, len(cells))):
            s, c = cells[cell]
            sequence = episode_seed_sequence(config.seed, p, s, c)
            tasks.append(
                EpisodeTask(
                    episode_id=episode_id(p, spec_names[s], condition_names[c]),
                    participant=p,
                    position=position,
                    spec=spec_names[s],
                    spec_index=s,
                    condition=condition_names[c],
                    condition_index=c,
                    seed=int(sequence.generate_state(1)[0] & 0x7FFFFFFF),
                    driver_entropy=(config.seed, EPISODE_KEY, p, s, c),
                )
            )
    return tasks


def participant_type_indices(config: StudyConfig, weights: np.ndarray) -> np.ndarray:
    """Each participant's type index, drawn from `weights` (see the module docstring)."""
    cumulative = np.cumsum(np.asarray(weights, dtype=float))
    cumulative /= cumulative[-1]
    draws = [
        np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(TYPE_KEY, p))).random()
        for p in range(config.participants)
    ]
    return np.minimum(np.searchsorted(cumulative, draws, side="right"), len(cumulative) - 1)


def participant_types(config: StudyConfig) -> list[str] | None:
    """The participants' true type names, or None when the study has no [drivers] population."""
    if config.driver_population is None:
        return None

    population = load_driver_population(config.driver_population)
    names = population.names
    return [names[int(i)] for i in participant_type_indices(config, population.weights)]


def _check_type_model(model: DriverModel, nominal: DriverModel, config: StudyConfig, name: str) -> None:
    if (tuple(model.trust_levels) != tuple(nominal.trust_levels)
            or tuple(model.incident_types) != tuple(nominal.incident_types)):
        raise InputError(
            config.driver_population or config.source_path, f"types.{name}",
            f"trust levels {list(model.trust_levels)} / incidents {list(model.incident_types)} differ "
            f"from the AV's driver model ({list(nominal.trust_levels)} / {list(nominal.incident_types)})",
            "give every type the trust levels and incident types of the study's driver model")


def participant_models(config: StudyConfig, nominal: DriverModel) -> list[DriverModel] | None:
    """The participants' driver models, or None when every driver is the nominal model."""
    if config.population is None and config.driver_population is None:
        return None

    spread = population_config_from_dict(config.population, config.source_path, nominal.n_trust)
    rng = np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(POPULATION_KEY,)))
    if config.driver_population is None:
        return sample_population(nominal, config.participants, spread, rng)

    population = load_driver_population(config.driver_population)
    for driver_type in population.types:
        _check_type_model(driver_type.model, nominal, config, driver_type.name)
    indices = participant_type_indices(config, population.weights)
    bases = [population.types[int(i)].model for i in indices]
    if config.population is None:
        return bases
    return [sample_individual(base, spread, rng, label=f"individual {p}") for p, base in enumerate(bases)]
