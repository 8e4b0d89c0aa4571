"""Driver populations sampled from `[population]` settings: K driver types around a nominal model.

Each type is one draw of `participants.population.sample_individual` (Dirichlet rows, a logit shift
of the takeover probabilities, a Dirichlet initial distribution, all around the nominal model), so
a type differs from the nominal model exactly as one individual of a sampled `[population]` does. The
types get equal prior weights. Every draw goes through the Generator passed in: the same seed gives
the same population file byte for byte.
"""

from __future__ import annotations

import numpy as np

from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import DriverPopulation, DriverType
from trustroute.participants.population import PopulationConfig, sample_individual

MAX_TYPES = 1_000


def sample_driver_population(nominal: DriverModel, n_types: int, config: PopulationConfig,
                             rng: np.random.Generator, provenance: str = "") -> DriverPopulation:
    """`n_types` types sampled around `nominal` with `config`'s spread, equal weights."""
    if not 1 <= n_types <= MAX_TYPES:
        raise ValueError(f"n_types must lie in [1, {MAX_TYPES}], got {n_types}")
    types = tuple(
        DriverType(name=f"type{k + 1}", weight=1.0 / n_types,
                   model=sample_individual(nominal, config, rng, label=f"type{k + 1}"))
        for k in range(n_types)
    )
    return DriverPopulation(types=types, source_path="",
                            provenance=provenance or f"{n_types} types sampled around "
                            f"{nominal.source_path}: {config}")
