"""`trustroute peer storm`: Storm's bounds beside ours, and the one-line error without stormpy."""

from __future__ import annotations

import json

import pytest

from tests.cli import run_cli


def test_without_stormpy_the_command_says_how_to_install_it(capsys, monkeypatch):
    import trustroute.policies.peer.storm as storm

    monkeypatch.setattr(storm, "storm_available", lambda: False)
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", "4")
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "stormpy" in err and "trustroute[peer]" in err


def test_belief_atoms_are_a_one_line_error(capsys):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, _, err = run_cli(capsys, "peer", "storm", "specs/phi1.toml", "--horizon", "4")
    assert code == 2 and err.count("\n") == 1 and "hightrust" in err


def test_json_reports_both_sides(capsys):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, _ = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", "6",
                           "--time-limit", "1", "--json")
    assert code == 0
    result = json.loads(out)
    storm, ours = result["storm"], result["ours"]
    assert result["overlap"] and ours["gap"] <= 1e-11
    assert storm["lower"] - 1e-6 <= ours["lower"] <= storm["upper"] + 1e-6
    assert storm["lower_seconds"] >= 0 and ours["seconds"] >= 0


@pytest.mark.parametrize("horizon", ["0", "5"])
def test_no_route_within_the_horizon_is_an_answer_not_an_error(capsys, horizon):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", horizon,
                             "--time-limit", "1", "--json")
    assert code == 0 and "Traceback" not in err
    result = json.loads(out)
    assert (result["storm"]["lower"], result["storm"]["upper"]) == (0.0, 0.0)
    assert "no reachable state" in result["storm"]["note"]
    assert result["ours"]["upper"] <= 1e-11 and result["overlap"]
    code, out, _ = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", horizon,
                           "--time-limit", "1")
    assert code == 0 and "note: no reachable state" in out


BAD_PEER_INPUTS = [
    ["missing.toml", "--horizon", "3"],
    ["README.md", "--horizon", "3"],
    ["specs/phi2.toml", "--horizon", "3"],
    ["specs/phi1_strict.toml"],
    ["specs/phi1_trust.toml", "--town", "missing.json", "--horizon", "3"],
    ["specs/phi1_trust.toml", "--driver", "missing.json", "--horizon", "3"],
    ["specs/phi1_trust.toml", "--driver", "participants/data/driver_population_three_types.json",
     "--horizon", "3"],
    ["specs/phi1_trust.toml", "--horizon", "-1"],
]


@pytest.mark.parametrize("args", BAD_PEER_INPUTS)
def test_every_input_storm_cannot_take_is_one_line_and_exit_2(capsys, args):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, err = run_cli(capsys, "peer", "storm", *args, "--time-limit", "1")
    assert code == 2 and out == "" and "Traceback" not in err
    assert err.strip().count("\n") == 0 or err.startswith("Usage:"), err


def test_a_storm_failure_is_one_line_and_exit_2(capsys, monkeypatch):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    import stormpy.pomdp

    def refuse(*_args, **_kwargs):
        raise RuntimeError("InvalidPropertyException: a product Storm cannot take")

    monkeypatch.setattr(stormpy.pomdp, "verify_with_belief_unfolding", refuse)
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", "6",
                             "--time-limit", "1")
    assert code == 2 and out == "" and err.count("\n") == 1 and "Storm cannot take" in err
