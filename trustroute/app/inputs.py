"""The inputs of a run, by packaged name or path, with the packaged defaults filled in.

Every argument naming an input is an object, a path, a packaged name (trustroute/core/packaged.py)
or None for the packaged default. A packaged spec written for a packaged town other than the
default (`SPEC_TOWNS`: `city5` on `city`, `csomor5` on `csomor`) brings its town when none is given.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.core.packaged import SPEC_TOWNS, SPECS
from trustroute.core.wording import shown_value
from trustroute.networks.town import Town, load_town
from trustroute.participants.driver_model import DriverModel, load_driver_model
from trustroute.participants.driver_population import DriverPopulation, load_driver_population
from trustroute.policies.logic.spec import Spec, load_spec

PathLike = str | Path


def check_given(value: object, kind: type, given: str) -> None:
    """The one check of an input argument's type (a script can pass anything): None (the default),
    a `kind` object, or a file path or packaged name; an InputError naming `given` otherwise."""
    if value is None or isinstance(value, kind | str | os.PathLike):
        return
    name = kind.__name__
    raise InputError(given, "", f"expected a {name}, a file path or a packaged name, "
                     f"got {shown_value(value)}",
                     f"pass a {name}, the path of its file or its packaged name")


def packaged_spec_town(spec: Spec | PathLike) -> str | None:
    """The packaged town a packaged spec is written for (None: the default town, or not a packaged
    spec). An existing file wins over a packaged name, as everywhere; a path into the packaged
    folder (the repository's specs/ links there) is the packaged spec."""
    check_given(spec, Spec, "spec")
    if isinstance(spec, Spec):
        return None
    path = SPECS.resolve(spec)
    return SPEC_TOWNS.get(path.stem) if SPECS.ships(path) else None


def town_of(town: Town | PathLike | None, spec: Spec | PathLike | None = None, given: str = "--town") -> Town:
    """A Town from an object, a file, a packaged name, or None: the town a packaged `spec` is
    written for, else the packaged default town (`given`: how the command line takes it)."""
    check_given(town, Town, given)
    if isinstance(town, Town):
        return town
    if town is None and spec is not None:
        town = packaged_spec_town(spec)
    return load_town(town, given)


def driver_of(driver: DriverModel | PathLike | None) -> DriverModel:
    """A DriverModel from an object, a file, a packaged name, or None (the packaged model)."""
    check_given(driver, DriverModel, "--driver")
    return driver if isinstance(driver, DriverModel) else load_driver_model(driver)


def population_of(population: DriverPopulation | PathLike, given: str = "--population") -> DriverPopulation:
    """A DriverPopulation from an object, a file or a packaged name (`given`: how the command line
    takes it)."""
    check_given(population, DriverPopulation, given)
    if isinstance(population, DriverPopulation):
        return population
    return load_driver_population(population, given)


@dataclass(frozen=True, eq=False)
class Inputs:
    """The loaded inputs of a run: a town, a spec checked against it, and one driver model or a
    driver population (`population_source`: its file, for messages)."""

    town: Town
    spec: Spec
    driver: DriverModel | None = None
    population: DriverPopulation | None = None
    population_source: str = ""

    @property
    def model(self) -> DriverModel:
        """The driver model the spec's trust levels are read on (a population's first type's)."""
        if self.population is not None:
            return self.population.types[0].model
        assert self.driver is not None
        return self.driver


def spec_of(spec: Spec | PathLike, town: Town, driver: DriverModel | None = None,
            source: str = "") -> Spec:
    """A Spec from an object, a file or a packaged name, checked against `town` (and the trust
    levels of `driver`; `source` names the driver's file in messages)."""
    check_given(spec, Spec, "spec")
    if isinstance(spec, Spec):
        return spec
    if driver is None:
        return load_spec(spec, town)
    return load_spec(spec, town, driver.n_trust, source or driver.source_path)


def load_inputs(spec: Spec | PathLike, town: Town | PathLike | None = None,
                driver: DriverModel | PathLike | None = None,
                population: DriverPopulation | PathLike | None = None) -> Inputs:
    """The inputs of a run: `driver` or `population` (not both; neither: the packaged model)."""
    if driver is not None and population is not None:
        raise InputError("--population", "", "a driver model and a driver population were both given",
                         "give --driver or --population, not both (a population's types are full "
                         "driver models)")
    loaded_town = town_of(town, spec)
    if population is not None:
        loaded = population_of(population)
        source = str(population) if not isinstance(population, DriverPopulation) else loaded.source_path
        return Inputs(town=loaded_town, spec=spec_of(spec, loaded_town, loaded.types[0].model, source),
                      population=loaded, population_source=source)
    model = driver_of(driver)
    return Inputs(town=loaded_town, spec=spec_of(spec, loaded_town, model), driver=model)
