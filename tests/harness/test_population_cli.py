"""`--population` on the command line: one type is today's synthesis and policy file; bad
population files, specs naming absent types and policies made for another population are one
line and exit code 2."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli
from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH
from trustroute.policies.belief.trust_state_relaxation import RELAXATION_MARGIN

SPEC = "specs/phi1.toml"


def one_type_file(tmp_path: Path) -> Path:
    path = tmp_path / "one.json"
    path.write_text(json.dumps({"format": "trustroute-driver-population", "version": 1, "types": [
        {"name": "nominal", "weight": 1.0, "model_file": str(DEFAULT_DRIVER_MODEL_PATH)}]}))
    return path


@pytest.mark.slow
def test_one_type_population_synthesizes_todays_policy_file(tmp_path, capsys):
    today = tmp_path / "today" / "policy.json"
    code, out, _ = run_cli(capsys, "synth", SPEC, "--horizon", "7", "--json", "--out", str(today))
    assert code == 0
    typed = tmp_path / "typed" / "policy.json"
    code2, out2, _ = run_cli(capsys, "synth", SPEC, "--horizon", "7", "--json", "--out", str(typed),
                             "--population", str(one_type_file(tmp_path)))
    assert code2 == 0
    first, second = json.loads(out), json.loads(out2)
    assert (first["lower"], first["upper"]) == (second["lower"], second["upper"])
    assert first["stats"]["policy_rows"] == second["stats"]["policy_rows"] > 0
    assert today.with_suffix(".npz").read_bytes() == typed.with_suffix(".npz").read_bytes()
    # the documents are the same bytes but for the wall-clock seconds
    texts = [re.sub(r'"seconds": [^,]*,', "", p.read_text()) for p in (today, typed)]
    assert texts[0] == texts[1] and "population" not in texts[1]
    assert second["population"]["type_values"][0]["lower"] >= second["lower"] - 1e-12


def test_bad_population_file_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    document = json.loads(EXAMPLE_POPULATION_PATH.read_text())
    document["types"][1]["weight"] = 0.5
    bad.write_text(json.dumps(document))
    code, _, err = run_cli(capsys, "synth", SPEC, "--horizon", "3", "--population", str(bad),
                           "--out", str(tmp_path / "p.json"))
    assert_one_line_error(code, err, str(bad), "weights sum to")
    assert not (tmp_path / "p.json").exists()


def test_spec_naming_an_absent_type_names_both_files(tmp_path, capsys):
    spec = tmp_path / "typed.toml"
    spec.write_text(Path(SPEC).read_text().replace("[states]", "[type_beliefs]\nsure = { types = "
                                                  "[\"stubborn\"], above = 0.5 }\n\n[states]"))
    for command in (("synth", str(spec), "--horizon", "3", "--out", str(tmp_path / "p.json")),
                    ("spec", "check", str(spec))):
        code, _, err = run_cli(capsys, *command, "--population", str(EXAMPLE_POPULATION_PATH))
        assert_one_line_error(code, err, str(spec), str(EXAMPLE_POPULATION_PATH), "stubborn")


def test_routing_with_a_policy_made_for_another_population_is_exit_2(tmp_path, capsys):
    policy = tmp_path / "robust.json"
    code, out, _ = run_cli(capsys, "synth", SPEC, "--horizon", "3", "--json", "--out", str(policy),
                           "--population", str(EXAMPLE_POPULATION_PATH))
    assert code == 0, out
    assert json.loads(policy.read_text())["population_hash"]
    other = tmp_path / "other.json"
    document = json.loads(EXAMPLE_POPULATION_PATH.read_text())
    document["types"][0]["weight"], document["types"][1]["weight"] = 0.3, 0.4
    other.write_text(json.dumps(document))
    code, _, err = run_cli(capsys, "evaluate", SPEC, str(policy), "--population", str(other))
    assert_one_line_error(code, err, str(policy), "another driver population")
    code, _, err = run_cli(capsys, "evaluate", SPEC, str(policy))
    assert_one_line_error(code, err, str(policy), "for a driver population (hash ",
                          "), not for a single driver model", "pass the driver population it was made for",
                          "re-run trustroute synth without --population")
    code, out, _ = run_cli(capsys, "evaluate", SPEC, str(policy), "--population",
                           str(EXAMPLE_POPULATION_PATH), "--json", "--max-junctions", "3")
    assert code == 0
    assert len(json.loads(out)["population"]["type_values"]) == 3


@pytest.mark.slow
def test_run_draws_the_driver_type_and_filters_with_the_type_aware_model(tmp_path, capsys):
    code, out, err = run_cli(capsys, "run", SPEC, "--population", str(EXAMPLE_POPULATION_PATH),
                             "--policy", "free", "--seed", "4", "--json", "--out", str(tmp_path / "logs"))
    assert code == 0, err
    summary = json.loads(out)
    assert summary["driver_type"] in ("builder", "flat", "wary")
    import pandas as pd

    roads = pd.read_parquet(tmp_path / "logs" / "roads.parquet")
    assert all(len(b) == 7 for b in roads["belief_after"])   # the trust marginal is logged


@pytest.mark.slow
def test_trust_state_spec_with_three_types_synthesizes_and_evaluates(tmp_path, capsys):
    out = tmp_path / "policy.json"
    code, text, _ = run_cli(capsys, "synth", "specs/phi1_trust.toml", "--horizon", "10", "--json",
                            "--out", str(out), "--population", str(EXAMPLE_POPULATION_PATH))
    assert code == 0
    made = json.loads(text)
    assert made["stats"]["method"].startswith("search over joint")
    assert 0 < made["lower"] <= made["upper"] <= made["lower"] + 1e-3
    types = made["population"]["type_values"]
    assert [t["name"] for t in types] == ["builder", "flat", "wary"]
    weights = made["population"]["weights"]
    assert sum(w * t["lower"] for w, t in zip(weights, types, strict=True)) >= made["lower"] - 1e-12
    assert json.loads(out.read_text())["kind"] == "joint-belief"
    code, text, _ = run_cli(capsys, "evaluate", "specs/phi1_trust.toml", str(out), "--population",
                            str(EXAMPLE_POPULATION_PATH), "--no-fallback", "--max-junctions", "10", "--json")
    assert code == 0
    assert json.loads(text)["population"]["type_values"] == types
    # the worst type: certified between the worst type's value and the bound of its own optimum
    code, text, _ = run_cli(capsys, "synth", "specs/phi1_trust.toml", "--horizon", "10", "--json",
                            "--out", str(tmp_path / "robust.json"), "--objective", "robust",
                            "--population", str(EXAMPLE_POPULATION_PATH))
    assert code == 0
    robust = json.loads(text)
    assert robust["lower"] == min(t["lower"] for t in robust["population"]["type_values"])
    assert robust["lower"] <= robust["upper"] <= min(robust["population"]["type_upper"]) + 1e-12
    # the flat type cannot satisfy phi1_trust within 10 junctions (its own bound is 0: the search's
    # allowance for rounding, RELAXATION_MARGIN, itself rounded up by a relative 1e-12 at most), so
    # the Bayes policy is robust-optimal already and no candidate prior is synthesized after it
    own = min(robust["population"]["type_upper"])
    assert RELAXATION_MARGIN <= own <= RELAXATION_MARGIN * (1 + 1e-12)
    assert robust["upper"] - robust["lower"] <= 1e-3
    assert len(robust["population"]["candidates"]) == 1
    assert robust["population"]["candidates_not_needed"] == 15
