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
