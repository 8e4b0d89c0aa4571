"""`trustroute baseline` and `trustroute evaluate` end to end (JSON output, exit codes)."""

from __future__ import annotations

import json

import pytest

from tests.cli import run_cli
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import baseline_route


def test_baseline_json(capsys, town):
    code, out, _ = run_cli(capsys, "baseline", "specs/phi1.toml", "--json")
    assert code == 0
    payload = json.loads(out)
    route = baseline_route(town, load_spec("specs/phi1.toml", town))
    assert payload["route"] == route
    assert payload["length_m"] == pytest.approx(town.route_length(route))
    assert 0.0 < payload["satisfaction_probability"] < 1.0
    # exact up to the outward rounding of certified bounds (policies/synthesis/rounding.py)
    lower, upper = payload["lower"], payload["upper"]
    assert lower <= payload["satisfaction_probability"] <= upper <= lower + 1e-11
    # the same certified bounds as `evaluate` of the free route gives
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi1.toml", "free", "--no-fallback", "--json")
    assert code == 0
    evaluated = json.loads(out)
    assert (payload["lower"], payload["upper"]) == (evaluated["lower"], evaluated["upper"])


def test_evaluate_free_json_matches_baseline(capsys):
    code, out, _ = run_cli(capsys, "baseline", "specs/phi2.toml", "--json")
    baseline_value = json.loads(out)["satisfaction_probability"]
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi2.toml", "free", "--json")
    assert code == 0
    payload = json.loads(out)
    assert payload["satisfaction_probability"] == pytest.approx(baseline_value, abs=1e-12)
    assert 1.0 <= payload["expected_final_trust"] <= 7.0
    assert payload["fallback_after"] == 20


def test_evaluate_rejects_an_unknown_policy_with_exit_code_2(capsys, tmp_path):
    code, out, err = run_cli(capsys, "evaluate", "specs/phi1.toml", str(tmp_path / "missing.json"))
    assert code == 2
    assert out == ""
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1


def test_evaluate_rejects_a_negative_fallback(capsys):
    code, _, err = run_cli(capsys, "evaluate", "specs/phi1.toml", "free", "--fallback-after", "-1")
    assert code == 2
    assert "fallback" in err


def test_baseline_of_a_trust_state_spec_is_the_joint_value_of_the_free_route(capsys):
    # phi1_trust tests the hidden trust: the free route's value is the joint unfolding's, as
    # `evaluate free --no-fallback` gives it
    code, out, err = run_cli(capsys, "baseline", "phi1_trust", "--json")
    assert code == 0, err
    payload = json.loads(out)
    code, out, _ = run_cli(capsys, "evaluate", "phi1_trust", "free", "--no-fallback", "--json")
    assert code == 0
    evaluated = json.loads(out)
    assert (payload["lower"], payload["upper"]) == (evaluated["lower"], evaluated["upper"])
    assert 0.0 < payload["lower"] <= payload["upper"] < 1.0


def test_baseline_text_prints_its_certified_interval_rounded_outward_as_evaluate_does(capsys):
    code, out, _ = run_cli(capsys, "baseline", "phi1", "--json")
    payload = json.loads(out)
    code, out, _ = run_cli(capsys, "baseline", "phi1")
    assert code == 0
    code, evaluated, _ = run_cli(capsys, "evaluate", "phi1", "free", "--no-fallback")
    shown = out.splitlines()[1].split("P(satisfied) in ")[1].split("]")[0] + "]"
    assert shown in evaluated
    low, high = (float(x) for x in shown.strip("[]").split(", "))
    assert low <= payload["lower"] <= payload["upper"] <= high
