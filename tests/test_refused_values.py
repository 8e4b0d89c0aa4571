"""A refused value is shown as Python writes it, by every loader (trustroute.core.wording.shown_value):
a string quoted, a number bare, so the string "5" written where a number goes never reads as the
number 5 the message asks for, nor the number 5 written where a name goes as the string '5'."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import trustroute
from trustroute.core.errors import InputError
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.harness.study.config import study_config_from_dict
from trustroute.networks.town import DEFAULT_TOWN_PATH, town_from_dict
from trustroute.networks.town_incidents import RoadFacts, incidents_from_file
from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH, driver_model_from_dict
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, driver_population_from_dict
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.routing.files import FORMAT, VERSION, read_policy_document


def loaded_after(path: Path | str, reader: Callable[[dict, str], object],
                 name: str) -> Callable[[Callable[[dict], None]], Callable[[Path], object]]:
    """A loader of the packaged file `path`'s data after `change`, read by `reader` as file `name`."""
    def with_change(change: Callable[[dict], None]) -> Callable[[Path], object]:
        def load(_: Path) -> object:
            data = json.loads(Path(path).read_text())
            change(data)
            return reader(data, name)
        return load
    return with_change


town = loaded_after(DEFAULT_TOWN_PATH, town_from_dict, "town.json")
driver_model = loaded_after(DEFAULT_DRIVER_MODEL_PATH, driver_model_from_dict, "model.json")
population = loaded_after(EXAMPLE_POPULATION_PATH, driver_population_from_dict, "population.json")


def policy(**document: object) -> Callable[[Path], object]:
    def load(folder: Path) -> object:
        path = folder / "policy.json"
        path.write_text(json.dumps({"format": FORMAT, "version": VERSION, **document}))
        return read_policy_document(path)
    return load


def incidents(kind: object) -> Callable[[Path], object]:
    def load(folder: Path) -> object:
        path = folder / "incidents.json"
        path.write_text(json.dumps({"a-b": kind}))
        return incidents_from_file(str(path), [RoadFacts("a-b", 100.0, 13.9)])
    return load


def study(**values: object) -> Callable[[Path], object]:
    def load(folder: Path) -> object:
        table = {"participants": 2, "seed": 1, "specs": ["phi1"], "conditions": ["free"], **values}
        document = {"study": table}
        return study_config_from_dict(document, "study.toml", folder)
    return load


def spec(name: str) -> Callable[[Path], object]:
    def load(_: Path) -> object:
        text = (PACKAGED_SPECS / "phi1.toml").read_text()
        return spec_from_text(text.replace('name = "phi1"', f"name = {json.dumps(name)}"), "spec.toml")
    return load


def first_junction(data: dict, value: object) -> None:
    data["junctions"][next(iter(data["junctions"]))] = value


def first_type(data: dict, key: str, value: object) -> None:
    data["types"][0][key] = value


# (what loads the bad input, the refusal's words): one case per message showing a refused value
CASES = [
    (town(lambda t: first_junction(t, "5")), "coordinates '5' are not two finite numbers"),
    (town(lambda t: t.update(geometry={"A-B": {"shape": [[0, 0], [1, 0]], "length": "5"}})),
     "length '5' is not a positive number of metres"),
    (town(lambda t: t.update(one_way=["AB"])), "'AB' is not a pair of junction names"),
    (town(lambda t: t["roads"].append(list(range(40)))),
     "[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16... is not a pair of junction names"),
    (incidents(5), "unknown incident type 5"),
    (driver_model(lambda m: m.update(trust_levels="5")), "'5' is not an increasing list of 2 to"),
    (population(lambda p: p.update(format=5)), "5 is not a driver-population file"),
    (population(lambda p: p.update(version="1")), "version '1' is not supported"),
    (population(lambda p: first_type(p, "name", 5)), "5 is not a type name"),
    (policy(version=str(VERSION)), f"policy file version '{VERSION}', this trustroute reads"),
    (policy(kind=5), "unknown policy kind 5 (only"),
    (policy(horizon="8"), "horizon '8' is not a junction count or null"),
    (policy(horizon=8, lower="0.5"), "lower bound '0.5' is not a probability"),
    (study(robust_objective=5), "unknown objective 5"),
    # a value too long for the line is cut, the cut marked (a quote cut off would read as a name)
    (spec("a" * 70 + "/"), "spec name '" + "a" * 36 + "... is not"),
]


@pytest.mark.parametrize(("load", "problem"), CASES, ids=[problem for _, problem in CASES])
def test_a_refused_value_is_shown_as_python_writes_it(tmp_path, load, problem):
    with pytest.raises(InputError) as error:
        load(tmp_path)
    assert problem in error.value.problem


def test_a_numpy_number_is_shown_as_the_number_it_is():
    """An initial trust given as numpy's int is refused as 9, not as numpy's repr of it."""
    with pytest.raises(InputError) as error:
        trustroute.run_episode("phi1", engine="model", initial_trust=np.int64(9))
    assert error.value.problem == "9 is not a trust level of the model"
