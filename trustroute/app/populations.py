"""Driver populations as the commands make them: types sampled around a nominal model
(`trustroute population sample`) and populations written to files (`trustroute fit --types`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from trustroute.app.inputs import driver_of
from trustroute.core.errors import InputError
from trustroute.core.validation import parse_toml, read_text
from trustroute.participants.driver_model import DEFAULT_REPORT_ACCURACY
from trustroute.participants.driver_population import (
    DriverPopulation,
    load_driver_population,
    write_driver_population,
)
from trustroute.participants.population import PopulationConfig, population_config_from_dict
from trustroute.participants.sampled_types import sample_driver_population

REPORT_ACCURACY = DEFAULT_REPORT_ACCURACY   # the packaged drivers' trust-report accuracy
NOMINAL = PopulationConfig()   # the [population] defaults: every driver the nominal model


def population_settings(config_path: str | None, concentration: float | None, spread: float | None,
                         n_trust: int):
    """The spread of sampled types: a TOML file's [population] table, overridden by the options."""
    table: dict = {}
    source = "--config"
    if config_path is not None:
        source = str(config_path)
        data = parse_toml(read_text(config_path, source, "the [population] settings",
                                    "pass a TOML file with a [population] table (e.g. a study config)"),
                          source, "population settings")
        table = dict(data.get("population") or {})
    if concentration is not None:
        table["concentration"] = concentration
    if spread is not None:
        table["takeover_spread"] = spread
    return population_config_from_dict(table, source, n_trust)


def sample_population(n_types: int, seed: int, out: Path, driver: str | None, config_path: str | None,
                      concentration: float | None, spread: float | None) -> tuple[DriverPopulation, Path]:
    """K types sampled around the nominal model (seeded), written to `out`: (population, path), the
    population as the file loads (its weights divided by their sum, docs/formats/driver_population.md),
    so the content hash said is the one every consumer of the file computes."""
    nominal = driver_of(driver)
    settings = population_settings(config_path, concentration, spread, nominal.n_trust)
    if math.isinf(settings.concentration) and settings.takeover_spread == 0:
        # --concentration cannot be inf (its range refuses it): a file's table or the default set it
        source, place = (config_path, "population") if config_path is not None else ("--concentration", "")
        raise InputError(source, place, f"concentration {settings.concentration:g} and takeover spread "
                         f"{settings.takeover_spread:g} give every type the nominal model",
                         "give a finite --concentration, a --takeover-spread above 0, or a --config "
                         "whose [population] table sets one")
    provenance = (f"trustroute population sample --types {n_types} --seed {seed} around "
                  f"{nominal.source_path}: concentration {settings.concentration:g}, takeover_spread "
                  f"{settings.takeover_spread:g}")
    result = sample_driver_population(nominal, n_types, settings, np.random.default_rng(seed), provenance)
    path = write_driver_population(result, out)
    return load_driver_population(path, "--out"), path


def write_population(population: DriverPopulation, path: Path) -> Path:
    """Write a population file atomically; returns its path."""
    return write_driver_population(population, path)
