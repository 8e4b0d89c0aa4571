"""Rerun recordings of episodes on an imported town's own SUMO net: the ego is logged on the net's
lanes along the driven roads' edges, the plan along the roads' shapes, the incidents where they
stood, every layer of the map in its draw order, a city's lines and markers thinner; `replay`
records an episode of a study on the town. The Ingolstadt scenario of sumo-rl (the `cities` extra):
a road of 0.2 m between two decision junctions is driven and recorded."""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import sumolib

from tests.cli import run_cli
from tests.harness.simulation.test_real_net_episode import DEMAND, INCIDENTS, NET, SPEC, TYPES
from trustroute.harness.simulation.episode import EpisodeOptions, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.rerun_log import (
    CITY_DETAIL,
    DRAW_ORDER,
    INCIDENT_HALF_SIZE,
    LANE_RADIUS,
    detail,
    lane_strips,
)
from trustroute.networks.town import load_town
from trustroute.networks.town_import import import_town
from trustroute.networks.town_map import map_frame
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.resolve import resolve_policy

NANOS = 1e9


def read_recording(path: Path) -> dict[str, list]:
    import rerun as rr

    entities: dict[str, list] = {}
    for chunk in rr.chunk.RrdReader(path).stream().to_chunks():
        entities.setdefault(chunk.entity_path, []).append(chunk)
    return entities


def column(chunks, suffix: str) -> tuple[np.ndarray, list]:
    """(times in seconds, values) of the component column ending in `suffix`; static rows at -1."""
    times, values = [], []
    for chunk in chunks:
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n.endswith(suffix)]
        if not names:
            continue
        if "sim_time" in batch.schema.names:
            times.append(batch.column("sim_time").cast(pa.int64()).to_numpy() / NANOS)
        else:
            times.append(np.full(batch.num_rows, -1.0))
        values.extend(batch.column(names[0]).to_pylist())
    if not times:
        return np.array([]), []
    joined = np.concatenate(times)
    order = np.argsort(joined, kind="stable")
    return joined[order], [values[i] for i in order]


def record_episode(town_path: Path, spec_path: Path, seed: int, rrd: Path):
    town = load_town(town_path)
    model = load_driver_model(None)
    spec = load_spec(str(spec_path), town)
    policy = resolve_policy("free", town, model, spec, None)
    driver = SyntheticDriver(model, np.random.default_rng(seed))
    record = run_episode(EpisodeSetup(town=town, driver_model=model, spec=spec), policy, driver, f"r{seed}",
                         seed, EpisodeOptions(rrd_path=rrd))
    return town, record, read_recording(rrd)


@pytest.fixture(scope="module")
def fokr(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fokr")
    shutil.copyfile(NET, folder / NET.name)
    (folder / "incidents.json").write_text(json.dumps(INCIDENTS))
    import_town(folder / NET.name, folder / "town.json", incidents_path=str(folder / "incidents.json"))
    (folder / "spec.toml").write_text(SPEC)
    town, record, entities = record_episode(folder / "town.json", folder / "spec.toml", 3, folder / "e.rrd")
    return {"folder": folder, "town": town, "record": record, "entities": entities,
            "net": sumolib.net.readNet(str(folder / NET.name), withInternal=True)}


def test_the_ego_is_logged_on_the_lanes_of_the_driven_roads_edges(fokr):
    town, record, entities, net = fokr["town"], fokr["record"], fokr["entities"], fokr["net"]
    times, strips = column(entities["/world/ego/box"], "LineStrips2D:strips")
    kinematics = record.kinematics
    np.testing.assert_allclose(times, kinematics["time"].to_numpy())
    centres = np.array([np.mean(np.asarray(s[0])[[0, 2, 3, 4]], axis=0) for s in strips]) * [1, -1]
    edges = {edge for road in record.roads["directed_road"] for edge in town.geometry[road].edges}
    on_edges = 0
    for (x, y), lane in zip(centres, kinematics["lane"], strict=True):
        shape = net.getLane(lane).getShape()
        # the logged centre lies on the lane SUMO reported, in the net's own coordinates
        assert sumolib.geomhelper.distancePointToPolygon((x, y), shape) < 0.5
        if not lane.startswith(":"):
            assert lane.rsplit("_", 1)[0] in edges   # an edge of the roads' edge lists
            on_edges += 1
    assert on_edges > len(kinematics) / 2
    # every road's edges were driven, in the recording's road states as in the roads table
    _, roads = column(entities["/state/road"], "StateChange:state")
    assert [r[0] for r in roads] == record.roads["directed_road"].tolist()


def test_the_plan_is_drawn_along_the_roads_shapes(fokr):
    town, record, entities = fokr["town"], fokr["record"], fokr["entities"]
    times, plans = column(entities["/world/ego/plan"], "LineStrips2D:strips")
    decided = record.roads.dropna(subset=["action"])
    decided = decided[decided["action"].astype(bool)]
    assert len(plans) == len(decided) > 3
    for plan, row in zip(plans, decided.itertuples(), strict=True):
        following = town.successor(row.directed_road, row.action)
        for strip, road in zip(plan, (row.directed_road, following), strict=True):
            np.testing.assert_allclose(np.asarray(strip) * [1, -1], town.geometry[road].shape, atol=0.05)
    np.testing.assert_allclose(times, decided["sim_time_out"].to_numpy())


def test_incidents_are_boxes_where_they_stood_sized_for_the_town(fokr):
    town, record, entities = fokr["town"], fokr["record"], fokr["entities"]
    placed = record.incidents.dropna(subset=["x"])
    assert len(placed) >= 2
    size = INCIDENT_HALF_SIZE * map_frame(town).unit * detail(town)
    for row in placed.itertuples():
        chunks = entities[f"/world/incidents/{row.index}_{row.incident}"]
        times, centres = column(chunks, "Boxes2D:centers")
        assert times[0] == row.injected_time
        np.testing.assert_allclose(centres[0][0], [row.x, -row.y], atol=0.01)
        _, halves = column(chunks, "Boxes2D:half_sizes")
        np.testing.assert_allclose(halves[0][0], [size, size], rtol=1e-6)
        cleared, _ = column(chunks, "Clear:is_recursive")
        np.testing.assert_allclose(cleared, [] if np.isnan(row.removed_time) else [row.removed_time])


def test_the_map_layers_and_a_city_scale(fokr):
    town, entities, net = fokr["town"], fokr["entities"], fokr["net"]
    unit = map_frame(town).unit
    lanes = entities["/world/lanes"][0].to_record_batch()
    assert len(lanes.column("LineStrips2D:strips")[0]) == len(lane_strips(net))
    _, radii = column(entities["/world/lanes"], "LineStrips2D:radii")
    assert radii[0][0] == pytest.approx(LANE_RADIUS * unit * detail(town), rel=1e-6)
    roads = entities["/world/roads"][0].to_record_batch()
    assert len(roads.column("LineStrips2D:strips")[0]) == len(town.geometry)
    orders = {}
    for name in ("lanes", "roads", "junctions", "incident_roads", "ego/plan", "ego/trail", "ego/box"):
        _, value = column(entities[f"/world/{name}"], "draw_order")
        orders[name] = value[0][0] if isinstance(value[0], list) else value[0]
    assert orders["lanes"] < orders["roads"] < orders["junctions"] < orders["ego/plan"]
    assert orders["incident_roads"] < orders["ego/plan"] < orders["ego/trail"] < orders["ego/box"]
    assert orders["ego/box"] == DRAW_ORDER["ego"]
    big = len(town.junctions) > 30
    assert detail(town) == (CITY_DETAIL if big else 1.0)


def test_replay_records_a_study_episode_on_the_imported_town(fokr, tmp_path, capsys):
    folder = fokr["folder"]
    config = tmp_path / "study.toml"
    config.write_text(f'[study]\nparticipants = 1\nseed = 3\nengine = "sumo"\n'
                      f'specs = ["{folder / "spec.toml"}"]\nconditions = ["free"]\n'
                      f'town = "{folder / "town.json"}"\nroutes = ["{TYPES}", "{DEMAND}"]\n')
    out = tmp_path / "study"
    code, text, err = run_cli(capsys, "study", str(config), "--out", str(out), "--json", "--no-report")
    assert code == 0, err
    rrd = tmp_path / "replay.rrd"
    code, text, err = run_cli(capsys, "replay", str(out), "p00000-spec-free", "--rrd", str(rrd), "--json")
    assert code == 0, err
    assert json.loads(text)["reproduced"] is True
    entities = read_recording(rrd)
    times, _ = column(entities["/world/ego/box"], "LineStrips2D:strips")
    assert len(times) > 100 and "/world/lanes" in entities


def ingolstadt_net() -> Path | None:
    spec = importlib.util.find_spec("sumo_rl")   # the `cities` extra, located without importing it
    if spec is None or not spec.submodule_search_locations:
        return None
    net = Path(spec.submodule_search_locations[0]) / "nets" / "RESCO" / "ingolstadt21"
    net = net / "ingolstadt21.net.xml"
    return net if net.is_file() else None


INGOLSTADT_SPEC = """name = "ingolstadt"
start = "1423242716-1782978609"
formula = "F (v1 & F v2)"

[states]
v1 = { junction = "267783873" }
v2 = { junction = "30624898" }
"""
SHORT_ROAD = "1782978609-313321254"   # one edge of 0.2 m between two decision junctions


@pytest.mark.skipif(ingolstadt_net() is None, reason="sumo-rl (the cities extra) is not installed")
def test_a_road_shorter_than_one_step_is_driven_and_recorded_on_ingolstadt(tmp_path):
    net = ingolstadt_net()
    shutil.copyfile(net, tmp_path / net.name)
    import_town(tmp_path / net.name, tmp_path / "town.json", rng=np.random.default_rng(1), incident_seed=1)
    (tmp_path / "spec.toml").write_text(INGOLSTADT_SPEC)
    town, record, entities = record_episode(tmp_path / "town.json", tmp_path / "spec.toml", 1,
                                            tmp_path / "e.rrd")
    assert town.geometry[SHORT_ROAD].length < 1.0
    route = record.roads["directed_road"].tolist()
    assert SHORT_ROAD in route and record.summary["end_reason"] == "accepted"
    # the short road is entered and closed at the commit point of the road before it
    roads = record.roads.set_index("directed_road")
    before = route[route.index(SHORT_ROAD) - 1]
    assert roads.loc[SHORT_ROAD, "sim_time_in"] == roads.loc[before, "sim_time_out"]
    assert detail(town) == CITY_DETAIL and len(town.junctions) > 200
    _, strips = column(entities["/world/ego/box"], "LineStrips2D:strips")
    assert len(strips) == len(record.kinematics)


def test_an_ego_at_the_end_of_an_unextended_route_is_named_as_such(fokr, monkeypatch):
    from trustroute.harness.simulation.real_roads import RealRoads

    monkeypatch.setattr(RealRoads, "extend_route", lambda self, sumo, vehicle, road, nxt: [])
    folder = fokr["folder"]
    with pytest.raises(RuntimeError, match="the ego left the net at the end of its route on 4_begin-71"):
        record_episode(folder / "town.json", folder / "spec.toml", 3, folder / "unextended.rrd")
