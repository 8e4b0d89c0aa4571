"""Driver-population files: round trip, identity, the packaged example, and one error per violation."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tests.cli import mutated, mutation_cases, refused_file
from trustroute.core.errors import InputError
from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH, load_driver_model
from trustroute.participants.driver_population import (
    EXAMPLE_POPULATION_PATH,
    DriverPopulation,
    DriverType,
    driver_population_from_dict,
    load_driver_population,
    single_type_population,
    write_driver_population,
)


def example() -> dict:
    return json.loads(EXAMPLE_POPULATION_PATH.read_text())


def test_example_has_three_distinct_types_summing_to_one():
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    assert population.names == ("builder", "flat", "wary")
    assert population.weights.sum() == pytest.approx(1.0, abs=1e-12)
    hashes = {t.model.content_hash for t in population.types}
    assert len(hashes) == 3
    flat = population.types[1].model
    # "flat": identity transitions, so trust never moves off its start
    assert np.array_equal(flat.trust_transition, np.broadcast_to(np.eye(7), flat.trust_transition.shape))
    with pytest.raises(ValueError):
        population.weights[0] = 0.5


def test_write_then_load_round_trips_and_keeps_the_hash(tmp_path):
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    path = write_driver_population(population, tmp_path / "pop.json")
    again = load_driver_population(path)
    assert again.content_hash == population.content_hash
    assert again.names == population.names
    assert not list(tmp_path.glob(".tmp-*"))


def test_hash_changes_with_weights_and_names():
    base = driver_population_from_dict(example(), "a")
    other = example()
    other["types"][0]["weight"], other["types"][1]["weight"] = 0.3, 0.4
    assert driver_population_from_dict(other, "b").content_hash != base.content_hash
    renamed = example()
    renamed["types"][0]["name"] = "builds"
    assert driver_population_from_dict(renamed, "c").content_hash != base.content_hash


def test_model_file_is_read_relative_to_the_population_file(tmp_path):
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "nominal.json").write_text(DEFAULT_DRIVER_MODEL_PATH.read_text())
    doc = {"format": "trustroute-driver-population", "version": 1,
           "types": [{"name": "nominal", "weight": 1.0, "model_file": "models/nominal.json"}]}
    (tmp_path / "pop.json").write_text(json.dumps(doc))
    population = load_driver_population(tmp_path / "pop.json")
    assert population.types[0].model.content_hash == load_driver_model().content_hash


@pytest.mark.parametrize(("model_file", "problem"), [
    ("nowhere.json", "cannot read the driver model 'nowhere.json' (No such file or directory)"),
    ("models", "the driver model 'models' is a directory"),
])
def test_a_model_file_that_cannot_be_read_is_placed_at_its_key(tmp_path, model_file, problem):
    (tmp_path / "models").mkdir()
    doc = {"format": "trustroute-driver-population", "version": 1,
           "types": [{"name": "nominal", "weight": 1.0, "model_file": model_file}]}
    path = tmp_path / "pop.json"
    error = refused_file(load_driver_population, doc, path)
    assert (error.source, error.place, error.problem) == (str(path), "types[0].model_file", problem)
    assert error.fix == ("set types[0].model_file to an existing driver model file, relative to the "
                         "population file's folder, or a packaged driver model name (driver_model, "
                         "driver_model_performance)")


@pytest.mark.parametrize("name", ["driver_model_performance", "driver_model_performance.json"])
def test_a_packaged_model_name_is_read_wherever_the_population_file_lies(tmp_path, monkeypatch, name):
    # the packaged-name rule holds from any folder, not only where the population's folder is "."
    doc = {"format": "trustroute-driver-population", "version": 1,
           "types": [{"name": "performance", "weight": 1.0, "model_file": name}]}
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "pop.json").write_text(json.dumps(doc))
    expected = load_driver_model("driver_model_performance").content_hash
    monkeypatch.chdir(tmp_path)
    for given in ("sub/pop.json", tmp_path / "sub" / "pop.json"):
        assert load_driver_population(given).types[0].model.content_hash == expected
    monkeypatch.chdir(tmp_path / "sub")
    assert load_driver_population("pop.json").types[0].model.content_hash == expected


def test_a_file_beside_the_population_wins_over_a_packaged_name(tmp_path):
    (tmp_path / "driver_model_performance.json").write_text(DEFAULT_DRIVER_MODEL_PATH.read_text())
    doc = {"format": "trustroute-driver-population", "version": 1,
           "types": [{"name": "nominal", "weight": 1.0, "model_file": "driver_model_performance.json"}]}
    (tmp_path / "pop.json").write_text(json.dumps(doc))
    population = load_driver_population(tmp_path / "pop.json")
    assert population.types[0].model.content_hash == load_driver_model().content_hash


def test_a_model_named_where_an_inline_model_goes_points_to_model_file(tmp_path):
    doc = {"format": "trustroute-driver-population", "version": 1,
           "types": [{"name": "nominal", "weight": 1.0, "model": "driver_model"}]}
    path = tmp_path / "pop.json"
    error = refused_file(load_driver_population, doc, path)
    assert (error.source, error.place) == (str(path), "types[0].model")
    assert error.problem == "expected a driver model (an object), got 'driver_model'"
    assert error.fix == 'to name a driver model file or a packaged model, write "model_file": "driver_model"'


def test_what_is_wrong_inside_a_model_file_names_that_file(tmp_path):
    (tmp_path / "m.json").write_text('{"trust_levels": [1, 2], "x": NaN}')
    doc = {"format": "trustroute-driver-population", "version": 1,
           "types": [{"name": "nominal", "weight": 1.0, "model_file": "m.json"}]}
    error = refused_file(load_driver_population, doc, tmp_path / "pop.json")
    assert (error.source, error.place) == (str(tmp_path / "m.json"), "x")


def test_single_type_population_is_its_model():
    model = load_driver_model()
    population = single_type_population(model)
    assert population.n_types == 1 and population.names == ("nominal",)
    assert population.types[0].model is model and population.weights.tolist() == [1.0]


def _drop_format(d):
    del d["format"]


def _wrong_format(d):
    d["format"] = "trustroute-driver-model"


def _bad_version(d):
    d["version"] = 2


def _no_types(d):
    d["types"] = []


def _unknown_key(d):
    d["weights"] = [1]


def _type_unknown_key(d):
    d["types"][1]["prior"] = 0.3


def _duplicate_name(d):
    d["types"][2]["name"] = "builder"


def _bad_name(d):
    d["types"][0]["name"] = "has space"


def _zero_weight(d):
    d["types"][0]["weight"] = 0.0
    d["types"][1]["weight"] = 0.7


def _weights_not_one(d):
    d["types"][0]["weight"] = 0.41


def _both_model_and_file(d):
    d["types"][0]["model_file"] = "x.json"


def _neither_model_nor_file(d):
    del d["types"][0]["model"]


def _missing_model_file(d):
    del d["types"][0]["model"]
    d["types"][0]["model_file"] = "does-not-exist.json"


def _other_trust_levels(d):
    model = d["types"][1]["model"]
    model["trust_levels"] = [1, 2, 3, 4, 5, 6, 8]


def _other_incidents(d):
    model = d["types"][2]["model"]
    model["incident_types"] = ["pedestrian", "obstacle", "truck", "none"]


def _bad_model(d):
    d["types"][2]["model"]["takeover_probability"]["truck"] = [0.5] * 6


CASES = [
    (_drop_format, "format", "missing key"),
    (_wrong_format, "format", "not a driver-population file"),
    (_bad_version, "version", "not supported"),
    (_no_types, "types", "expected a list of 1 to"),
    (_unknown_key, "weights", "unknown key"),
    (_type_unknown_key, "types[1].prior", "unknown key"),
    (_duplicate_name, "types[2].name", "appears twice"),
    (_bad_name, "types[0].name", "is not a type name"),
    (_zero_weight, "types[0].weight", "not a positive number"),
    (_weights_not_one, "types", "the weights sum to"),
    (_both_model_and_file, "types[0]", "exactly one of"),
    (_neither_model_nor_file, "types[0]", "exactly one of"),
    (_missing_model_file, "types[0].model_file", "cannot read the driver model 'does-not-exist.json'"),
    (_other_trust_levels, "types[1]", "trust levels"),
    (_other_incidents, "types[2]", "covers incidents"),
    (_bad_model, "takeover_probability.truck", "expected 7 numbers"),
]


@pytest.mark.parametrize("mutate, place, problem", mutation_cases(CASES))
def test_bad_population_file_is_one_input_error(tmp_path, mutate, place, problem):
    error = refused_file(load_driver_population, mutated(example(), mutate), tmp_path / "pop.json")
    message = error.one_line()
    assert "\n" not in message
    assert place in message and problem in message, message
    assert "(fix: " in message


def test_not_json_and_not_an_object(tmp_path):
    path = tmp_path / "pop.json"
    path.write_text("{ nope")
    with pytest.raises(InputError, match="not valid JSON"):
        load_driver_population(path)
    path.write_text("[1, 2]")
    with pytest.raises(InputError, match="top level"):
        load_driver_population(path)


@pytest.mark.parametrize("weights", [(0.3333333333, 0.3333333333, 0.3333333334), (0.4, 0.3, 0.3 - 5e-10)])
def test_weights_within_the_tolerance_are_loaded_as_a_distribution(weights):
    import math

    data = example()
    for entry, weight in zip(data["types"], weights, strict=True):
        entry["weight"] = weight
    population = driver_population_from_dict(data)
    assert abs(math.fsum(population.weights) - 1.0) <= 1e-15
    given = np.array(weights) / math.fsum(weights)
    assert np.allclose(population.weights, given, rtol=0, atol=1e-16)
    if math.fsum(weights) != 1.0:
        assert not np.array_equal(population.weights, np.array(weights))


@pytest.mark.parametrize("weights", [(0.3333333333, 0.3333333333, 0.3333333334), (0.4, 0.3, 0.3 - 5e-10),
                                     (1 / 3, 1 / 3, 1 / 3)])
def test_a_population_built_in_code_is_a_distribution_as_a_loaded_one_is(weights):
    """The one rule of the weights holds for a population built in code (the API, a sampled or a
    fitted population): within the tolerance of 1 they sum to exactly 1.0, the loaded file's
    weights, hash alike; farther off, the loaded file's one-line refusal."""
    import math

    data = example()
    for entry, weight in zip(data["types"], weights, strict=True):
        entry["weight"] = weight
    loaded = driver_population_from_dict(data)

    def built(with_weights: tuple[float, ...]) -> DriverPopulation:
        return DriverPopulation(tuple(DriverType(t.name, w, t.model)
                                      for t, w in zip(loaded.types, with_weights, strict=True)))

    assert math.fsum(built(weights).weights.tolist()) == 1.0
    assert built(weights).weights.tolist() == loaded.weights.tolist()
    assert built(weights).content_hash == loaded.content_hash
    off = (0.5, 0.5, 1e-8)
    with pytest.raises(InputError) as refused:
        built(off)
    for entry, weight in zip(data["types"], off, strict=True):
        entry["weight"] = weight
    with pytest.raises(InputError) as refused_loaded:
        driver_population_from_dict(data)
    assert (refused.value.source, refused.value.place) == ("<driver population>", "types")
    said = refused_loaded.value
    assert (refused.value.problem, refused.value.fix) == (said.problem, said.fix)


@pytest.mark.parametrize("weights", [(float("nan"), 0.5, 0.5), (1.5, -0.25, -0.25), (1.0, 0.0, 0.0),
                                     (float("inf"), 0.5, 0.5)])
def test_a_population_built_in_code_refuses_the_weights_a_file_may_not_hold(weights):
    """A weight that is not a finite number > 0 is refused in code as in a file, naming the type's
    weight with the file's words: a NaN passes the test of the sum, and negative weights that sum
    to 1 would weigh a type against the others."""
    data = example()
    types = driver_population_from_dict(data).types
    index = next(i for i, w in enumerate(weights) if not 0 < w < math.inf)
    with pytest.raises(InputError) as refused:
        DriverPopulation(tuple(DriverType(t.name, w, t.model) for t, w in zip(types, weights, strict=True)))
    assert refused.value.place == f"types[{index}].weight"
    data["types"][index]["weight"] = weights[index]
    if math.isfinite(weights[index]):   # JSON holds no NaN or infinity
        with pytest.raises(InputError) as refused_loaded:
            driver_population_from_dict(data)
        said = refused_loaded.value
        assert (refused.value.place, refused.value.problem, refused.value.fix) == (said.place, said.problem,
                                                                                   said.fix)


@pytest.mark.parametrize("weight", [True, "1", None])
def test_a_weight_that_is_no_number_is_refused_in_code_with_the_files_line(weight):
    """A bool, a string or None as a weight in code is the one-line refusal the file gives (not a
    TypeError, and True is no weight of 1)."""
    data = example()
    data["types"] = [{**data["types"][0], "weight": 1.0}]
    model = driver_population_from_dict(data).types[0].model
    with pytest.raises(InputError) as refused:
        DriverPopulation((DriverType("nominal", weight, model),))
    data["types"][0]["weight"] = weight
    with pytest.raises(InputError) as refused_loaded:
        driver_population_from_dict(data)
    said, given = refused_loaded.value, refused.value
    assert (given.place, given.problem, given.fix) == (said.place, said.problem, said.fix)


def test_a_numpy_or_fraction_weight_is_its_float():
    """A weight a script computed (numpy, fractions) is the float a file gives: the same weights,
    the same hash, a float in the file written."""
    from fractions import Fraction

    types = driver_population_from_dict(example()).types
    given = [Fraction(1, 2), np.float32(0.25), np.float64(0.25)][:len(types)]
    built = DriverPopulation(tuple(DriverType(t.name, w, t.model) for t, w in zip(types, given, strict=True)))
    plain = DriverPopulation(tuple(DriverType(t.name, float(w), t.model)
                                   for t, w in zip(types, given, strict=True)))
    assert [type(t.weight) for t in built.types] == [float] * len(types)
    assert built.content_hash == plain.content_hash
    assert json.dumps(built.to_dict()) == json.dumps(plain.to_dict())


def test_a_driver_model_and_a_population_given_for_each_other_say_which_they_are(tmp_path, capsys):
    """The natural mix-up (a fitted driver.json as --population, a fitted population as --driver):
    one line saying what the file is and where it goes, not the other format's first unknown key."""
    from tests.cli import run_cli

    model, population = str(DEFAULT_DRIVER_MODEL_PATH), str(EXAMPLE_POPULATION_PATH)
    code, out, err = run_cli(capsys, "population", "show", model)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert (f"{model}: top level: this is a driver model file, not a driver population (fix: pass it where a "
            "driver model goes (--driver)") in err, err
    with pytest.raises(InputError) as error:
        load_driver_model(population)
    assert (error.value.place, error.value.problem) == (
        "top level", "this is a driver population file, not a driver model")
    assert error.value.fix.startswith("pass it where a driver population goes (--population)")


def test_weights_loaded_once_load_again_unchanged():
    """A population written back as loaded keeps its weights and content hash: the loaded weights
    sum to exactly 1.0, and weights summing to exactly 1.0 are kept as they are."""
    import math

    rng = np.random.default_rng(7)
    for _ in range(300):
        data = example()
        weights = rng.dirichlet(np.ones(len(data["types"]))) * (1 + rng.uniform(-5e-10, 5e-10))
        for entry, weight in zip(data["types"], weights.tolist(), strict=True):
            entry["weight"] = weight
        first = driver_population_from_dict(data)
        assert math.fsum(first.weights.tolist()) == 1.0
        for entry, weight in zip(data["types"], first.weights.tolist(), strict=True):
            entry["weight"] = weight
        again = driver_population_from_dict(data)
        assert again.weights.tolist() == first.weights.tolist()
        assert again.content_hash == first.content_hash
