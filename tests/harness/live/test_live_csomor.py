"""A live study on an imported town (`csomor`, driven on its own SUMO net) and on a generated one
(`city`) serves and draws the net it drives: the station's /api/net lists exactly the lanes of the
net the town drives (`net_for`), a scripted participant drives its trial through the websocket,
and the replay of a live episode writes its recording on that net (on `csomor`, a net built from
the town's junctions would not even build)."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree

import pytest
from fastapi.testclient import TestClient

from tests.cli import run_cli
from trustroute.app.nets import net_for
from trustroute.harness.live.app import live_app
from trustroute.harness.live.scripted import ScriptedParticipant
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.plan import plan_episodes

from .test_live_manual import play_in

# slow: the csomor net is built from its packaged plain XML on first use
pytestmark = [pytest.mark.slow, pytest.mark.wallclock]

LIVE = """[study]
name = "{town}-live"
participants = 1
seed = 1
engine = "live"
town = "{town}"
specs = ["{town}5"]
conditions = ["free"]
"""


# One test per town: its played study is most of its time, and the suite's workers steal tests
# one at a time, so a town's study shared by two tests could be played once in each worker.
@pytest.fixture(params=["csomor", "city"])
def played(request, tmp_path_factory):
    """A live study on the town, open, whose one participant has driven their trial (pace 1000)."""
    folder = tmp_path_factory.mktemp(f"{request.param}-live")
    (folder / "live.toml").write_text(LIVE.format(town=request.param))
    config = load_study_config(folder / "live.toml")
    study = LiveStudy(config, folder / "study", ServerOptions(pace=1000.0, warm_up=False)).open()
    try:
        with TestClient(live_app(study)) as client:
            player = play_in(client, study, ScriptedParticipant(config, 0))
            assert not player.errors, player.errors[:3]   # no report refused as a flood, say
            yield study, client, folder
    finally:
        study.close()


def _lane_ids(net_file) -> set[str]:
    return {lane.get("id") for lane in ElementTree.parse(net_file).getroot().iter("lane")}


def test_the_station_serves_the_net_the_town_drives_and_the_replay_draws_on_it(played, capsys):
    study, client, folder = played
    response = client.get("/api/net", headers={"Authorization": f"Bearer {study.experimenter_token}"})
    assert response.status_code == 200, response.text
    town = study.context.town
    served = {lane["id"] for lane in response.json()["lanes"]}
    assert served == _lane_ids(net_for(town))
    # the town's roads run on the served net's edges (the net's own ids, not "U-V")
    edges = {lane.rsplit("_", 1)[0] for lane in served}
    assert all(edge in edges for road in town.geometry.values() for edge in road.edges)
    # the scripted participant's trial was driven and logged
    assert (study.study_dir / "parts").is_dir() and any((study.study_dir / "parts").iterdir())
    # the replay of the live episode writes its recording on the driven net
    (task,) = plan_episodes(study.config)
    rrd = folder / "live.rrd"
    code, _, err = run_cli(capsys, "replay", str(study.study_dir), task.episode_id, "--rrd", str(rrd))
    assert code == 0, err
    assert rrd.stat().st_size > 0
