"""The episodes of a study: who drives which (spec, condition) in which position, with which seed.

Cells are the (spec, condition) pairs in config order (φ1-aware, φ1-free, φ2-aware, φ2-free for
the paper); participant p drives them in the order of row p of the Williams design
(harness/study/latin_square.py). Every random quantity is derived with numpy's SeedSequence
from the study seed and fixed keys, never from the order in which episodes run or complete:

- participant p's driver model: `sample_population` with SeedSequence(seed, spawn_key=(2,)),
  all participants at once (nominal for every participant when there is no [population]);
- episode (p, spec s, condition c): SeedSequence(seed, spawn_key=(1, p, s, c)); its first
  32-bit word seeds the simulator (SUMO), the sequence itself seeds the driver's Generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.latin_square import participant_order
from trustroute.participants.driver_model import DriverModel

EPISODE_KEY = 1
POPULATION_KEY = 2


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


def participant_models(config: StudyConfig, nominal: DriverModel) -> list[DriverModel] | None:
    """The participants' driver models, or None when every driver is the nominal model."""
    if config.population is None:
        return None
    from trustroute.participants.population import population_config_from_dict, sample_population

    population = population_config_from_dict(config.population, config.source_path, nominal.n_trust)
    rng = np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(POPULATION_KEY,)))
    return sample_population(nominal, config.participants, population, rng)
