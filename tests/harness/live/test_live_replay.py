"""`trustroute replay` of a live episode re-draws it from its log: the Rerun recording holds the
logged ticks (positions, the person's mode), roads and incidents, and nothing is re-simulated."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from tests.cli import run_cli
from trustroute.core.dataset import part_path, read_kinematics, read_roads
from trustroute.harness.cli import cli
from trustroute.harness.live.scripted import ScriptedParticipant
from trustroute.harness.simulation.rerun_log import on_screen
from trustroute.harness.study.plan import plan_episodes

from .conftest import tiny_config
from .test_live_manual import play

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


def column(chunks, suffix: str) -> tuple[np.ndarray, list]:
    """(sim times in seconds, values) of the recording's component column ending in `suffix`."""
    rows = []
    for chunk in chunks:
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n.endswith(suffix)]
        if names and "sim_time" in batch.schema.names:
            times = batch.column("sim_time").cast("int64").to_pylist()
            rows += zip(times, batch.column(names[0]).to_pylist(), strict=True)
    rows.sort(key=lambda row: row[0])
    return np.array([t / 1e9 for t, _ in rows]), [value for _, value in rows]


def test_replay_of_a_live_episode_draws_its_log_without_simulating(tmp_path, monkeypatch, capsys):
    import rerun as rr

    import trustroute.harness.simulation.episode as episode

    config = tiny_config(tmp_path, participants=1, specs=("phi2",))
    play(tmp_path, ScriptedParticipant(config, 0, by_hand=True))
    study_dir = tmp_path / "study"
    (task,) = plan_episodes(config)

    def no_simulation(*args, **kwargs):
        raise AssertionError("a live episode's replay must not run SUMO")

    monkeypatch.setattr(episode, "run_episode", no_simulation)
    monkeypatch.setattr(episode, "sumo_session", no_simulation)
    rrd = tmp_path / "live.rrd"
    result = CliRunner().invoke(cli, ["replay", str(study_dir), task.episode_id, "--rrd", str(rrd), "--json"])
    assert result.exit_code == 0, result.output
    payload = json.loads(result.output)
    ticks = read_kinematics(study_dir)
    roads = read_roads(study_dir)
    assert payload["drawn_from_log"] and payload["ticks"] == len(ticks) and rrd.stat().st_size > 0
    assert payload["route"] == list(roads["directed_road"])

    entities: dict[str, list] = {}
    for chunk in rr.chunk.RrdReader(rrd).stream().to_chunks():
        entities.setdefault(chunk.entity_path, []).append(chunk)
    times, strips = column(entities["/world/ego/box"], "LineStrips2D:strips")
    np.testing.assert_allclose(times, ticks["time"].to_numpy())
    centres = np.array([np.mean(np.asarray(s[0])[[0, 2, 3, 4]], axis=0) for s in strips])
    np.testing.assert_allclose(centres, on_screen(ticks[["x", "y"]].to_numpy()), atol=1e-2)
    _, colours = column(entities["/world/ego/box"], "LineStrips2D:colors")
    manual = (ticks["mode"] == "manual").to_numpy()
    assert manual.any()   # the person's mode, tick by tick
    np.testing.assert_array_equal(np.array([c[0] for c in colours]) == 0xE62828FF, manual)
    _, logged_roads = column(entities["/state/road"], "StateChange:state")
    assert [r[0] for r in logged_roads] == list(roads["directed_road"])

    part_path(study_dir, task.episode_id).unlink()   # an episode without a part: one line, exit 2
    code, _, err = run_cli(capsys, "replay", str(study_dir), task.episode_id)
    assert code == 2 and err.count("\n") == 1 and "no part" in err
