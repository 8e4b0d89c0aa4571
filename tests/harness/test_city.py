"""The packaged city end to end: `spec check`, `baseline`, `evaluate` and `synth` accept `city5` on
`--town city` (the synthesized lower bound never below the trust-free route's value minus the gap),
a small study on it runs and replays, an episode drives the real net with the scenario's own
demand, and `demo --town city` runs its study."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli import cli_json, cli_study, run_cli
from tests.extras import needs_cities_extra

pytestmark = [pytest.mark.slow, needs_cities_extra]
# A road of city5's trust-free route 0.2 m long: the ego crosses it within one step.
SHORT_ROAD = "356699998-364445380"
# Units of synthesis work for city5 at H = 40: about 1.5 s here, 3 094 policy rows.
WORK_LIMIT = 1_000_000


@pytest.fixture(scope="module")
def synthesized() -> dict:
    """city5 at H = 40 stopped by a work limit (its bounds hold though it has not converged),
    written where the study's "aware" policy for city5 at H = 40 is cached: `demo --town city`
    then reads it instead of synthesizing for minutes (its synthesis is measured by bench_city)."""
    from trustroute import load_driver_model, load_spec, load_town
    from trustroute.harness.cli import main
    from trustroute.policies.resolve import aware_cache_path

    town = load_town("city")
    out = aware_cache_path(town, load_driver_model(), load_spec("city5", town), None, horizon=40)
    out.parent.mkdir(parents=True, exist_ok=True)

    with pytest.raises(SystemExit) as exit_info:
        main(["synth", "city5", "--town", "city", "--horizon", "40", "--work-limit", str(WORK_LIMIT),
              "--out", str(out)])
    assert exit_info.value.code == 0
    return {"policy": out}


def test_spec_check_baseline_evaluate_and_synth_accept_the_city(capsys, synthesized):
    check = cli_json(capsys, "spec", "check", "city5", "--town", "city")
    assert [w["junctions"] for w in check["waypoints"]] == [7, 5, 5, 4, 6]
    baseline = cli_json(capsys, "baseline", "city5", "--town", "city")
    assert baseline["junctions"] == 33 and SHORT_ROAD in baseline["route"]
    free = cli_json(capsys, "evaluate", "city5", "free", "--town", "city", "--no-fallback")
    # exact up to the outward rounding of evaluate's bounds (policies/synthesis/rounding.py)
    assert free["lower"] <= baseline["satisfaction_probability"] <= free["upper"] <= free["lower"] + 1e-11
    policy = cli_json(capsys, "evaluate", "city5", str(synthesized["policy"]), "--town", "city",
                   "--fallback-after", "40")
    document = json.loads(Path(synthesized["policy"]).read_text())
    lower, upper = document["lower"], document["upper"]
    assert 0.0 <= lower <= upper <= 1.0
    # U is sound, so it is at least the trust-free value (whether or not the search converged)
    assert lower >= baseline["satisfaction_probability"] - (upper - lower)
    # the policy written achieves its certified lower bound (within H = 40, and more after)
    assert policy["lower"] >= lower - 1e-9


def test_a_small_study_on_the_city_runs_and_replays(tmp_path, capsys, synthesized):
    episodes = cli_study(capsys, tmp_path / "city.toml", f"""[study]
participants = 2
seed = 3
engine = "model"
specs = ["city5"]
conditions = ["free", "{synthesized['policy']}"]
town = "city"
routes = ["city"]
horizon = 40
fallback_after = 40
""", tmp_path / "study")
    assert len(episodes) == 4 and set(episodes["end_reason"]) <= {"accepted", "destination", "rejected"}
    replay = cli_json(capsys, "replay", str(tmp_path / "study"), str(episodes["episode_id"].iloc[0]))
    assert replay["reproduced"] and replay["roads"] >= 28


def test_an_episode_drives_the_city_with_its_own_demand(tmp_path, capsys):
    summary = cli_json(capsys, "run", "city5", "--town", "city", "--routes", "city", "--policy", "free",
                    "--seed", "2", "--sumo-files", str(tmp_path / "sumo"))
    # the trust-free route to its end, across the 0.2 m road, among the scenario's own vehicles
    assert summary["end_reason"] in ("accepted", "destination") and summary["junctions"] == 33
    assert SHORT_ROAD in summary["route"]
    vehicles = (tmp_path / "sumo" / "routes.rou.xml").read_text().count("<vehicle ")
    assert vehicles > 100


def test_demo_runs_on_the_city(tmp_path, capsys, synthesized):
    code, out, err = run_cli(capsys, "demo", "--town", "city", "--engine", "model", "--participants", "1",
                             "--out", str(tmp_path / "demo"), "--workers", "1", "--json")
    assert code == 0, err
    payload = json.loads(out)
    manifest = json.loads((tmp_path / "demo" / "manifest.json").read_text())
    config = manifest["config"]
    assert payload["engine"] == "model" and not payload["failed"]
    assert config["horizon"] == 40 and Path(config["specs"][0]).name == "city5.toml"
    assert Path(config["town"]).name == "city.json" and len(config["routes"]) == 1
