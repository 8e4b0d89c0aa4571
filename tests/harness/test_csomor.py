"""The packaged town `csomor` (RouteRL's OpenStreetMap net of Csömör) end to end: `spec check`,
`baseline`, `evaluate` and `synth` accept `csomor5` on `--town csomor` (the synthesized lower bound
never below the trust-free route's value minus the gap, and the written policy achieves it), an
episode drives the real net among randomTrips.py's background traffic, and a small model-engine
study on it runs and replays."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli import cli_json, cli_study

pytestmark = pytest.mark.slow
# Units of synthesis work for csomor5 at H = 40: about 1.5 s here, 4 413 policy rows (at half of it
# nothing is synthesized yet, and the policy is only its fallback).
WORK_LIMIT = 2_000_000


@pytest.fixture(scope="module")
def synthesized(tmp_path_factory) -> Path:
    """csomor5 at H = 40 stopped by a work limit (docs/synthesis.md, "Work limit"): the same policy
    of a few thousand rows on any machine, with bounds that hold though it has not converged."""
    from trustroute.harness.cli import main

    out = tmp_path_factory.mktemp("csomor-synth") / "csomor5_h40.json"
    with pytest.raises(SystemExit) as exit_info:
        main(["synth", "csomor5", "--town", "csomor", "--horizon", "40", "--work-limit", str(WORK_LIMIT),
              "--out", str(out)])
    assert exit_info.value.code == 0
    return out


def test_spec_check_baseline_evaluate_and_synth_accept_csomor(capsys, synthesized):
    check = cli_json(capsys, "spec", "check", "csomor5", "--town", "csomor")
    assert [w["junctions"] for w in check["waypoints"]] == [8, 6, 6, 6, 6]
    baseline = cli_json(capsys, "baseline", "csomor5", "--town", "csomor")
    assert baseline["junctions"] == 32 <= 40   # the trust-free route fits the horizon
    free = cli_json(capsys, "evaluate", "csomor5", "free", "--town", "csomor", "--no-fallback")
    # exact up to the outward rounding of evaluate's bounds (policies/synthesis/rounding.py)
    assert free["lower"] <= baseline["satisfaction_probability"] <= free["upper"] <= free["lower"] + 1e-11
    document = json.loads(synthesized.read_text())
    lower, upper = document["lower"], document["upper"]
    assert 0.0 <= lower <= upper <= 1.0
    assert lower >= baseline["satisfaction_probability"] - (upper - lower)
    policy = cli_json(capsys, "evaluate", "csomor5", str(synthesized), "--town", "csomor",
                   "--fallback-after", "40")
    assert policy["lower"] >= lower - 1e-9


def test_an_episode_drives_csomor_among_background_traffic(tmp_path, capsys):
    summary = cli_json(capsys, "run", "csomor5", "--town", "csomor", "--policy", "free", "--seed", "2",
                    "--background", "10", "--sumo-files", str(tmp_path / "sumo"))
    assert summary["end_reason"] in ("accepted", "destination") and summary["junctions"] == 32
    routes = (tmp_path / "sumo" / "routes.rou.xml").read_text()
    assert routes.count("<trip ") + routes.count("<vehicle ") > 50


def test_a_small_study_on_csomor_runs_and_replays(tmp_path, capsys, synthesized):
    episodes = cli_study(capsys, tmp_path / "csomor.toml", f"""[study]
participants = 1
seed = 3
engine = "model"
specs = ["csomor5"]
conditions = ["free", "{synthesized}"]
town = "csomor"
horizon = 40
fallback_after = 40
""", tmp_path / "study")
    assert len(episodes) == 2 and set(episodes["end_reason"]) <= {"accepted", "destination", "rejected"}
    for episode_id in episodes["episode_id"]:
        replay = cli_json(capsys, "replay", str(tmp_path / "study"), str(episode_id))
        assert replay["reproduced"] and replay["roads"] >= 20
