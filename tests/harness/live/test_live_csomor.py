"""A live study on an imported town (`csomor`, driven on its own SUMO net) serves that net: the
station's /api/net lists exactly the lanes of the net the town drives (`net_for`), not a net built
from the town's junctions."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import pytest
from fastapi.testclient import TestClient

from trustroute.app.nets import net_for
from trustroute.harness.live.app import live_app
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.context import study_context

pytestmark = pytest.mark.slow   # the csomor net is built from its packaged plain XML on first use

CSOMOR_LIVE = """[study]
name = "csomor-live"
participants = 1
seed = 1
engine = "live"
town = "csomor"
specs = ["csomor5"]
conditions = ["free"]
"""


def _lane_ids(net_file) -> set[str]:
    return {lane.get("id") for lane in ElementTree.parse(net_file).getroot().iter("lane")}


def test_the_station_serves_the_net_an_imported_town_drives(tmp_path):
    (tmp_path / "live.toml").write_text(CSOMOR_LIVE)
    study = LiveStudy(load_study_config(tmp_path / "live.toml"), tmp_path / "study",
                      ServerOptions(pace=1000.0)).open()
    try:
        client = TestClient(live_app(study))
        response = client.get("/api/net", headers={"Authorization": f"Bearer {study.experimenter_token}"})
        assert response.status_code == 200, response.text
        town = study_context(study.config).town
        served = {lane["id"] for lane in response.json()["lanes"]}
        assert served == _lane_ids(net_for(town))
        # the town's roads run on the served net's edges (the net's own ids, not "U-V")
        edges = {lane.rsplit("_", 1)[0] for lane in served}
        assert all(edge in edges for road in town.geometry.values() for edge in road.edges)
    finally:
        study.close()


def test_the_replay_of_a_live_episode_on_csomor_draws_on_the_driven_net(tmp_path, capsys):
    from tests.cli import run_cli
    from trustroute.harness.live.scripted import ScriptedParticipant
    from trustroute.harness.study.plan import plan_episodes

    from .test_live_manual import play_in

    (tmp_path / "live.toml").write_text(CSOMOR_LIVE)
    config = load_study_config(tmp_path / "live.toml")
    study = LiveStudy(config, tmp_path / "study", ServerOptions(pace=1000.0, warm_up=False)).open()
    try:
        with TestClient(live_app(study)) as client:
            play_in(client, study, ScriptedParticipant(config, 0))
    finally:
        study.close()
    (task,) = plan_episodes(config)
    rrd = tmp_path / "live.rrd"
    code, _, err = run_cli(capsys, "replay", str(tmp_path / "study"), task.episode_id, "--rrd", str(rrd))
    assert code == 0, err
    assert rrd.stat().st_size > 0
