"""Malformed driver-model files: each gives its own one-line error and exit code 2 through the CLI."""

from __future__ import annotations

import json

import pytest

from tests.cli import assert_file_refused, assert_one_line_error, mutated, mutation_cases, run_cli
from trustroute.participants.driver_model import (
    DEFAULT_DRIVER_MODEL_PATH,
    driver_model_from_dict,
    load_driver_model,
)


def default_model() -> dict:
    return json.loads(DEFAULT_DRIVER_MODEL_PATH.read_text())


def short_takeover_row(m: dict) -> None:
    m["takeover_probability"]["truck"] = m["takeover_probability"]["truck"][:6]


def non_square_matrix(m: dict) -> None:
    m["trust_transition"]["obstacle"]["takeover"] = [row[:6] for row in
                                                     m["trust_transition"]["obstacle"]["takeover"]]


def row_not_summing_to_one(m: dict) -> None:
    m["trust_transition"]["pedestrian"]["standstill"][3][0] += 1e-6


def takeover_above_one(m: dict) -> None:
    m["takeover_probability"]["obstacle"][0] = 1.2


def negative_matrix_entry(m: dict) -> None:
    row = m["trust_transition"]["truck"]["takeover"][2]
    row[0], row[1] = row[0] + row[1] + 0.1, -0.1


def failure_below_zero(m: dict) -> None:
    m["failure_probability"] = {"obstacle": [-0.1, 0, 0, 0, 0, 0, 0]}


def missing_fail_matrix(m: dict) -> None:
    matrix = m["trust_transition"]["truck"]["takeover"]
    m["trust_transition"]["truck"]["takeover"] = {"succ": matrix}


def missing_standstill_matrix(m: dict) -> None:
    del m["trust_transition"]["none"]["standstill"]


def missing_takeover_incident(m: dict) -> None:
    del m["takeover_probability"]["pedestrian"]


def extra_incident_entry(m: dict) -> None:
    m["takeover_probability"]["cow"] = [0.5] * 7


def text_in_probabilities(m: dict) -> None:
    m["takeover_probability"]["truck"][2] = "high"


def initial_belief_not_summing(m: dict) -> None:
    m["initial_belief"] = [0.2] * 7


def bad_trust_levels(m: dict) -> None:
    m["trust_levels"] = [1, 3, 2, 4, 5, 6, 7]


def trust_free_not_a_number(m: dict) -> None:
    m["trust_free_takeover_probability"]["truck"] = "often"


def missing_trust_free_incident(m: dict) -> None:
    del m["trust_free_takeover_probability"]["pedestrian"]


def extra_trust_free_incident(m: dict) -> None:
    m["trust_free_takeover_probability"]["cow"] = 0.5


# (mutation, the place the message must name, words of the specific problem)
CASES = [
    (short_takeover_row, "takeover_probability.truck", "expected 7 numbers, got shape (6,)"),
    (non_square_matrix, "trust_transition.obstacle.takeover", "expected a 7x7 matrix, got shape (7, 6)"),
    (row_not_summing_to_one, "trust_transition.pedestrian.standstill[3]", "row sums to 1.000001"),
    (takeover_above_one, "takeover_probability.obstacle", "must lie in [0, 1]"),
    (negative_matrix_entry, "trust_transition.truck.takeover", "must lie in [0, 1]"),
    (failure_below_zero, "failure_probability.obstacle", "must lie in [0, 1]"),
    (missing_fail_matrix, "trust_transition.truck.takeover.fail", "missing 'fail' matrix"),
    (missing_standstill_matrix, "trust_transition.none.standstill", "missing 'standstill' matrix"),
    (missing_takeover_incident, "takeover_probability.pedestrian", "missing takeover probabilities"),
    (extra_incident_entry, "takeover_probability.cow", "not in incident_types"),
    (text_in_probabilities, "takeover_probability.truck", "expected 7 numbers"),
    (initial_belief_not_summing, "initial_belief", "sums to 1.4"),
    (bad_trust_levels, "trust_levels", "not an increasing list"),
    (trust_free_not_a_number, "trust_free_takeover_probability.truck", "not a probability"),
    (missing_trust_free_incident, "trust_free_takeover_probability.pedestrian",
     "missing trust-free takeover probability for 'pedestrian'"),
    (extra_trust_free_incident, "trust_free_takeover_probability.cow", "not in incident_types"),
]


@pytest.mark.parametrize("mutate, place, problem", mutation_cases(CASES))
def test_malformed_driver_model_gives_its_error_and_exit_2(tmp_path, capsys, mutate, place, problem):
    assert_file_refused(capsys, load_driver_model, "--driver", mutated(default_model(), mutate),
                        tmp_path / "driver.json", place, problem)


def test_row_within_tolerance_is_accepted():
    data = default_model()
    data["trust_transition"]["pedestrian"]["standstill"][3][0] += 1e-10
    driver_model_from_dict(data, "<test>")


def test_town_incident_missing_from_model(tmp_path, capsys):
    """The model is valid on its own but does not cover 'truck', which the default town uses."""
    data = default_model()
    data["incident_types"].remove("truck")
    for key in ("takeover_probability", "trust_transition", "trust_free_takeover_probability"):
        del data[key]["truck"]
    path = tmp_path / "driver.json"
    path.write_text(json.dumps(data))
    load_driver_model(path)
    code, out, err = run_cli(capsys, "model", "--driver", str(path))
    assert_one_line_error(code, err, str(path), "incident_types", "uses incident 'truck'")
    assert out == ""


def test_bad_json(tmp_path, capsys):
    path = tmp_path / "driver.json"
    path.write_text('{"trust_levels": [1, 2, 3\n')
    code, _, err = run_cli(capsys, "model", "--driver", str(path))
    assert_one_line_error(code, err, str(path), "line 2 column", "not valid JSON")


def test_missing_file(tmp_path, capsys):
    code, _, err = run_cli(capsys, "model", "--driver", str(tmp_path / "absent.json"))
    assert_one_line_error(code, err, "absent.json", "cannot read the driver model")


def test_trust_free_table_may_be_left_out_whole_and_round_trips_without_it():
    data = default_model()
    del data["trust_free_takeover_probability"]
    model = driver_model_from_dict(data, "<test>")
    assert model.trust_free_takeover_probability == {}
    again = driver_model_from_dict(json.loads(json.dumps(model.to_dict())), "<again>")
    assert again.content_hash == model.content_hash and again.trust_free_takeover_probability == {}


def test_performance_dependent_model_round_trips(tmp_path):
    data = default_model()
    data["failure_probability"] = {"obstacle": [0.3, 0.2, 0.1, 0.1, 0.05, 0.05, 0.0]}
    matrix = data["trust_transition"]["obstacle"]["standstill"]
    shifted = [row[1:] + row[:1] for row in matrix]
    data["trust_transition"]["obstacle"]["standstill"] = {"succ": matrix, "fail": shifted}
    model = driver_model_from_dict(data, "<test>")
    assert model.depends_on_performance
    i = model.incident_index("obstacle")
    assert model.trust_transition[i, 0, 1].tolist() == shifted
    again = driver_model_from_dict(json.loads(json.dumps(model.to_dict())), "<again>")
    assert again.content_hash == model.content_hash


def true_in_takeover(m: dict) -> None:
    m["takeover_probability"]["truck"][0] = True


def false_in_failure(m: dict) -> None:
    m["failure_probability"] = {"obstacle": [False] * 7}


def true_in_initial_belief(m: dict) -> None:
    m["initial_belief"] = [True, 0, 0, 0, 0, 0, 0]


def true_in_matrix(m: dict) -> None:
    matrix = m["trust_transition"]["obstacle"]["takeover"]
    matrix[0] = [True] + [False] * 6


def true_in_performance_matrix(m: dict) -> None:
    matrix = [[1.0 if i == j else 0.0 for j in range(7)] for i in range(7)]
    flagged = [row[:] for row in matrix]
    flagged[6][6] = True
    m["trust_transition"]["none"]["standstill"] = {"succ": matrix, "fail": flagged}


# JSON true/false would pass as 1/0 through a float conversion (bool is an int in Python); every
# one is refused where a number is expected, each at its place.
BOOL_CASES = [
    (true_in_takeover, "takeover_probability.truck", "expected 7 numbers, not true or false"),
    (false_in_failure, "failure_probability.obstacle", "expected 7 numbers, not true or false"),
    (true_in_initial_belief, "initial_belief", "expected 7 numbers, not true or false"),
    (true_in_matrix, "trust_transition.obstacle.takeover", "expected a matrix of numbers, not true or false"),
    (true_in_performance_matrix, "trust_transition.none.standstill.fail", "not true or false"),
]


@pytest.mark.parametrize("mutate, place, problem", mutation_cases(BOOL_CASES))
def test_true_or_false_is_not_a_probability(tmp_path, capsys, mutate, place, problem):
    error = assert_file_refused(capsys, load_driver_model, "--driver", mutated(default_model(), mutate),
                                tmp_path / "driver.json", place, problem)
    assert "true and false are not numbers" in error.fix


def test_numbers_equal_to_the_refused_booleans_are_accepted():
    data = default_model()
    data["initial_belief"] = [1, 0, 0, 0, 0, 0, 0]
    data["failure_probability"] = {"obstacle": [0, 0, 0, 0, 0, 0, 1]}
    model = driver_model_from_dict(data, "<test>")
    assert model.initial_belief.tolist() == [1.0, 0, 0, 0, 0, 0, 0]
    assert model.failure_probability[model.incident_index("obstacle"), 6] == 1.0
