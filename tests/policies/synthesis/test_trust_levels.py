"""Any number of trust levels the driver model defines; mismatched specs fail with one line, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.cli import run_cli
from trustroute.core.errors import InputError
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.exact_search import exact_optimum
from trustroute.policies.synthesis.settings import SynthesisSettings


def five_level_driver(default: DriverModel) -> DriverModel:
    """The default model with trust levels 1..7 merged into 5 (pairs 1-2, 6-7 summed)."""
    groups = [[0, 1], [2], [3], [4], [5, 6]]
    merge = np.zeros((7, 5))
    for j, members in enumerate(groups):
        merge[members, j] = 1.0
    mean = merge / merge.sum(axis=0)          # average rows within a group
    transition = np.einsum("ij,...ik,kl->...jl", mean, default.trust_transition, merge)
    return DriverModel(trust_levels=(1, 2, 3, 4, 5), incident_types=default.incident_types,
                       takeover_probability=default.takeover_probability @ mean,
                       failure_probability=default.failure_probability @ mean,
                       trust_transition=transition, initial_belief=np.full(5, 0.2),
                       trust_free_takeover_probability=dict(default.trust_free_takeover_probability),
                       source_path="<five levels>")


SPEC = """name = "five"
start = "E-A"
formula = "(!low) U (v1 & F high)"
[states]
v1 = ["B-G", "F-G", "I-G"]
[beliefs.low]
coeffs = COEFFS_LOW
offset = 0.35
[beliefs.high]
coeffs = COEFFS_HIGH
offset = 0.3
"""


def test_five_trust_levels_synthesise_and_bracket_the_optimum(town, driver):
    model = five_level_driver(driver)
    pomdp = build_pomdp(town, model)
    spec = spec_from_text(SPEC.replace("COEFFS_LOW", "[1, 0, 0, 0, 0]")
                          .replace("COEFFS_HIGH", "[0, 0, 0, 0, 1]"), "<five>", town)
    horizon = 6
    optimum = exact_optimum(pomdp, spec, horizon)
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=30))
    assert result.lower - 1e-12 <= optimum <= result.upper + 1e-12
    assert optimum > 0.1
    online = evaluate(pomdp, spec, result.policy,
                      EvaluationSettings(fallback_after=None, max_junctions=horizon))
    assert online.lower >= result.lower - 1e-12


def test_seven_coefficients_for_a_five_level_model_is_one_line_exit_2(town, driver, tmp_path: Path,
                                                                         capsys):
    model = five_level_driver(driver)
    spec_path = tmp_path / "seven.toml"
    spec_path.write_text(SPEC.replace("COEFFS_LOW", "[1, 0, 0, 0, 0, 0, 0]")
                         .replace("COEFFS_HIGH", "[0, 0, 0, 0, 0, 0, 1]"))
    spec = spec_from_text(spec_path.read_text(), str(spec_path), town)
    with pytest.raises(InputError, match="5 trust levels"):
        synthesize(build_pomdp(town, model), spec, SynthesisSettings(horizon=4))
    driver_path = tmp_path / "five.json"
    driver_path.write_text(json.dumps(model.to_dict()))
    code, out, err = run_cli(capsys, "synth", str(spec_path), "--driver", str(driver_path),
                             "--horizon", "4", "--out", str(tmp_path / "p.json"))
    assert code == 2
    lines = [line for line in err.strip().splitlines() if line]
    assert len(lines) == 1 and "Traceback" not in err
    assert "seven.toml" in lines[0] and "7 coefficients" in lines[0] and "5 trust levels" in lines[0]
    assert not (tmp_path / "p.json").exists()


def test_paper_rule_output_names_the_belief_mdp_and_the_bayes_value(tmp_path: Path, capsys):
    code, out, err = run_cli(capsys, "synth", "specs/phi1.toml", "--horizon", "8", "--belief-rule",
                             "paper", "--out", str(tmp_path / "p.json"), "--json")
    assert code == 0, err
    payload = json.loads(out)
    assert "authors' belief MDP" in payload["bounds_refer_to"]
    real = payload["bayes_process_value"]
    assert 0.0 <= real["lower"] <= real["upper"] <= 1.0 and real["max_junctions"] == 8
    code, out, err = run_cli(capsys, "synth", "specs/phi1.toml", "--horizon", "8", "--belief-rule",
                             "paper", "--out", str(tmp_path / "q.json"))
    assert "refer to the authors' belief MDP" in out and "real (Bayes) process" in out
