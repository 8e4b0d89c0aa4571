"""Episodes on an imported town's own SUMO net: the ego drives exactly the roads' edge lists, the
incidents stand on the edges of their road, the net's hash is checked, background traffic comes
from randomTrips.py or the scenario's route files, and run, study, analyze and replay accept the
town (the eclipse-sumo wheel's fokr_bs_demo net)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import sumo

from tests.cli import run_cli
from tests.networks.sumo_nets import WHEEL_NODES, WHEEL_ROADS, build_plain_net
from trustroute.core.errors import InputError
from trustroute.harness.simulation.background import CHECK_EVERY, STUCK_SECONDS, JamRelief, trips_seed
from trustroute.harness.simulation.episode import EGO_ID, EpisodeOptions, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.incidents.obstacle import BLOCKED_SECONDS
from trustroute.harness.simulation.sumo_start import SumoConfig
from trustroute.networks.real_net import road_edges, town_net_file
from trustroute.networks.sumo_net import find_binary
from trustroute.networks.town import load_town, town_from_dict
from trustroute.networks.town_import import import_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.resolve import resolve_policy

GAME = Path(sumo.SUMO_HOME) / "tools" / "game" / "fokr_bs_demo"
NET = GAME / "fokr_bs.net.xml.gz"
DEMAND = GAME / "15_16_veh.trips.xml.gz"
TYPES = GAME / "vtypes_default.add.xml"
INCIDENTS = {"71-83": "truck", "83-38": "obstacle", "38-10": "truck", "10-24": "truck",
             "10-38": "obstacle", "83-71": "truck", "38-83": "pedestrian", "97-38": "obstacle"}
SPEC = """name = "fokr"
start = "4_begin-71"
formula = "F (v1 & F v2)"

[states]
v1 = ["10-24"]
v2 = ["83-71"]
"""


@pytest.fixture(scope="module")
def city(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("city")
    shutil.copyfile(NET, folder / NET.name)
    (folder / "incidents.json").write_text(json.dumps(INCIDENTS))
    import_town(folder / NET.name, folder / "town.json", incidents_path=str(folder / "incidents.json"))
    (folder / "spec.toml").write_text(SPEC)
    return {"folder": folder, "town": folder / "town.json", "spec": folder / "spec.toml",
            "net": folder / NET.name}


class Watcher:
    """Per step: the ego's edges in the order driven, where each incident vehicle first stood, and
    which background vehicles were on the net."""

    def __init__(self) -> None:
        self.edges: list[str] = []
        self.objects: dict[str, tuple[str, tuple[str, ...]]] = {}
        self.background: set[str] = set()
        self.route: tuple[str, ...] = ()

    def __call__(self, sumo_module, ego, mode, road) -> None:
        if not ego.road.startswith(":") and (not self.edges or self.edges[-1] != ego.road):
            self.edges.append(ego.road)
        for vehicle in sumo_module.vehicle.getIDList():
            if vehicle.startswith("inc") and vehicle not in self.objects:
                self.objects[vehicle] = (sumo_module.vehicle.getRoadID(vehicle),
                                         tuple(sumo_module.vehicle.getRoute(vehicle)))
            elif vehicle.startswith("bg") or vehicle[:1].isdigit():
                self.background.add(vehicle)
        self.route = tuple(sumo_module.vehicle.getRoute(EGO_ID))   # SUMO's route of the ego


def episode(city, seed: int, config: SumoConfig | None = None):
    town = load_town(city["town"])
    model = load_driver_model(None)
    spec = load_spec(str(city["spec"]), town)
    return town, *drive(town, spec, model, seed, config)


def drive(town, spec, model, seed: int, config: SumoConfig | None = None, overrides: dict | None = None):
    policy = resolve_policy("free", town, model, spec, None)
    watcher = Watcher()
    driver = SyntheticDriver(model, np.random.default_rng(seed))
    options = EpisodeOptions(config=config if config is not None else SumoConfig(), observer=watcher,
                             scene_overrides=overrides or {})
    record = run_episode(EpisodeSetup(town=town, driver_model=model, spec=spec), policy, driver, f"e{seed}",
                         seed, options)
    return record, watcher


def check_route(town, record, watcher) -> None:
    """SUMO's route of the ego is the roads' edge lists one after another (from the start road's
    edge the ego departs on), and the ego was seen on those edges only, in that order."""
    route = record.roads["directed_road"].tolist()
    expected = [edge for road in route for edge in town.geometry[road].edges]
    start_edges = town.geometry[route[0]].edges
    assert len(watcher.route) > len(expected) - len(start_edges)
    assert list(watcher.route) == expected[len(expected) - len(watcher.route):]
    seen = iter(watcher.route)
    assert all(edge in seen for edge in watcher.edges)   # a subsequence, in order


def test_the_ego_drives_the_concatenated_edge_lists(city):
    town, record, watcher = episode(city, 2)
    assert len(record.roads) > 5
    check_route(town, record, watcher)


@pytest.mark.slow
def test_the_ego_drives_a_city_net_with_short_edges(tmp_path):
    """The wheel's DRT net (OpenStreetMap, 96 town junctions): edges a few metres long between
    junctions without a choice are passed within one step."""
    net = Path(sumo.SUMO_HOME) / "tools" / "game" / "DRT" / "osm.net.xml"
    # incident seed 5: the route below meets a pedestrian road with sidewalks on both sides
    town = import_town(net, tmp_path / "drt.json", rng=np.random.default_rng(5), incident_seed=5).town
    start = town.states[0]
    targets = sorted(town.reachable_states(start),
                     key=lambda road: (-town.route_length(town.shortest_route(start, [road])), road))
    (tmp_path / "spec.toml").write_text(f'name = "drt"\nstart = "{start}"\nformula = "F v1"\n\n'
                                        f'[states]\nv1 = ["{targets[0]}"]\n')
    town = load_town(tmp_path / "drt.json")
    model = load_driver_model(None)
    record, watcher = drive(town, load_spec(str(tmp_path / "spec.toml"), town), model, 1,
                            overrides={"pedestrian": {"timing": "late"}})
    assert record.summary["end_reason"] == "accepted" and record.summary["junctions"] > 10
    check_route(town, record, watcher)
    # Its streets have sidewalks and crossings: a late pedestrian steps onto the crossing at the
    # start of the incident's edge, in front of the ego, which stops for them.
    persons = record.incidents[record.incidents["incident"] == "pedestrian"]
    placed = persons[persons["sumo_ids"].notna()]
    assert len(placed) >= 1
    assert (placed["min_pedestrian_distance"] < 10).any()


def test_incidents_stand_on_the_edges_of_their_road(city):
    town, record, watcher = episode(city, 3)
    incidents = record.incidents.set_index("index")
    placed = {kind: 0 for kind in ("obstacle", "truck")}
    for vehicle, (edge, vehicle_route) in watcher.objects.items():
        index = int(vehicle.split(".")[0].removeprefix("inc"))
        road = incidents.loc[index, "directed_road"]
        kind = vehicle.split(".")[1]
        u, v = road.split("-")
        if kind == "obstacle":
            assert edge in town.geometry[road].edges
        elif kind == "truck":
            # it drives the road the other way (arriving there, maybe from a road leading in)
            assert vehicle_route[-1] in town.geometry[f"{v}-{u}"].edges
        placed[kind] = placed.get(kind, 0) + 1
    assert placed["obstacle"] >= 1 and placed["truck"] >= 1
    # The pedestrian's road 38-83 starts at a junction without a crossing over it: the road is
    # driven without the person.
    assert "38-83" in record.roads["directed_road"].tolist()
    pedestrian = incidents[incidents["incident"] == "pedestrian"]
    assert pedestrian["sumo_ids"].isna().all() and not any(".pedestrian" in v for v in watcher.objects)


def test_a_changed_net_is_one_line_naming_the_file(city, tmp_path, capsys):
    folder = tmp_path / "changed"
    folder.mkdir()
    shutil.copyfile(city["net"], folder / NET.name)
    shutil.copyfile(city["town"], folder / "town.json")
    town = load_town(folder / "town.json")
    assert town_net_file(town) == folder / NET.name
    with (folder / NET.name).open("ab") as handle:
        handle.write(b"\0")
    with pytest.raises(InputError, match="has changed since the town was imported"):
        town_net_file(town)
    code, out, err = run_cli(capsys, "run", str(city["spec"]), "--town", str(folder / "town.json"))
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and str(folder / NET.name) in err and "re-import" in err


def test_background_traffic_from_random_trips_is_seeded(city):
    config = SumoConfig(background_vehicles=30)
    _, first, seen = episode(city, 4, config)
    _, again, seen_again = episode(city, 4, config)
    assert len(seen.background) >= 5 and seen.background == seen_again.background
    assert first.kinematics["x"].tolist() == again.kinematics["x"].tolist()
    assert trips_seed(4) != trips_seed(5)


def test_background_traffic_from_the_scenario_route_file(city, tmp_path, capsys):
    code, out, err = run_cli(capsys, "run", str(city["spec"]), "--town", str(city["town"]), "--routes",
                             str(DEMAND), "--seed", "1")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "veh_car" in err   # its types missing
    code, out, err = run_cli(capsys, "run", str(city["spec"]), "--town", str(city["town"]), "--routes",
                             str(TYPES), "--routes", str(DEMAND), "--seed", "1", "--json")
    assert code == 0, err
    assert json.loads(out)["end_reason"] == "accepted"
    config = SumoConfig(route_files=(str(TYPES), str(DEMAND)))
    _, _, seen = episode(city, 1, config)
    assert len(seen.background) >= 5


@pytest.mark.slow
def test_a_small_sumo_study_on_the_imported_town(city, tmp_path, capsys):
    config = tmp_path / "study.toml"
    config.write_text(f'[study]\nparticipants = 2\nseed = 5\nengine = "sumo"\n'
                      f'specs = ["{city["spec"]}"]\nconditions = ["aware", "free"]\n'
                      f'town = "{city["town"]}"\nhorizon = 10\nroutes = ["{TYPES}", "{DEMAND}"]\n')
    out = tmp_path / "study"
    code, text, err = run_cli(capsys, "study", str(config), "--out", str(out), "--json", "--no-report")
    assert code == 0, err
    payload = json.loads(text)
    assert payload["planned"] == 4 and payload["failed"] == []
    code, text, err = run_cli(capsys, "analyze", str(out), "--json")
    assert code == 0, err
    assert json.loads(text)["cells"]
    code, text, err = run_cli(capsys, "replay", str(out), "p00001-spec-free", "--no-rrd", "--json")
    assert code == 0, err
    assert json.loads(text)["reproduced"] is True


def wheel_town(folder: Path, opposites: bool):
    """The importer tests' wheel net (every junction a decision point, 1 lane each way), with
    netconvert's opposite lanes or without, an obstacle on every road from a corner to the centre."""
    net = build_plain_net(folder, "wheel", WHEEL_NODES, WHEEL_ROADS)
    if opposites:
        subprocess.run([find_binary("netconvert"), "-s", str(net), "--opposites.guess", "true",
                        "-o", str(net), "--no-warnings"], check=True, capture_output=True)
    (folder / "incidents.json").write_text(json.dumps({f"{c}-e": "obstacle" for c in "abcd"}))
    import_town(net, folder / "town.json", incidents_path=str(folder / "incidents.json"))
    (folder / "spec.toml").write_text('name = "wheel"\nstart = "b-a"\nformula = "F v1"\n\n'
                                      '[states]\nv1 = ["e-c"]\n')
    town = load_town(folder / "town.json")
    return town, load_spec(str(folder / "spec.toml"), town)


@pytest.mark.parametrize("opposites", [True, False])
def test_an_obstacle_is_overtaken_through_the_opposite_lane_only_where_the_net_has_one(tmp_path, opposites):
    town, spec = wheel_town(tmp_path, opposites)
    roads = road_edges(town, town_net_file(town))
    assert all(edge.overtake is opposites for value in roads.values() for edge in value.edges)
    record, _ = drive(town, spec, load_driver_model(None), 1)
    assert record.roads["directed_road"].tolist()[1] == "a-e"
    row = record.incidents.set_index("directed_road").loc["a-e"]
    assert row["sumo_ids"].startswith("inc1.obstacle") and row["passed_time"] == row["passed_time"]
    kinematics = record.kinematics
    during = (kinematics["time"] >= row["injected_time"]) & (kinematics["time"] <= row["passed_time"])
    on_road = kinematics[during]
    in_opposite_lane = bool(on_road["lane"].str.startswith("e_a_").any())
    assert in_opposite_lane is opposites
    if not opposites:   # it waited behind the obstacle until the obstacle drove off
        assert on_road["speed"].min() < 0.5
        assert row["passed_time"] - row["injected_time"] > BLOCKED_SECONDS


def test_jam_relief_takes_out_stuck_background_vehicles_only():
    class Fake:
        def __init__(self) -> None:
            self.now = 0.0
            self.waiting = {"ego": 500.0, "inc3.obstacle": 500.0, "bg1": 130.0, "bg2": 30.0}
            self.simulation = type("S", (), {"getTime": lambda _: self.now})()
            self.vehicle = type("V", (), {"getIDList": lambda _: list(self.waiting),
                                          "getWaitingTime": lambda _, v: self.waiting[v],
                                          "remove": lambda _, v: self.waiting.pop(v)})()

    fake = Fake()
    relief = JamRelief("ego")
    relief.step(fake)
    assert set(fake.waiting) == {"ego", "inc3.obstacle", "bg1", "bg2"}   # not before the first look
    fake.now = CHECK_EVERY
    relief.step(fake)
    assert set(fake.waiting) == {"ego", "inc3.obstacle", "bg2"} and relief.removed == 1
    fake.waiting["bg2"] = STUCK_SECONDS
    fake.now += CHECK_EVERY / 2
    relief.step(fake)
    assert "bg2" in fake.waiting   # the next look comes CHECK_EVERY seconds after the last
    fake.now += CHECK_EVERY / 2
    relief.step(fake)
    assert set(fake.waiting) == {"ego", "inc3.obstacle"}


def test_the_ego_turns_only_where_the_net_has_a_connection(tmp_path):
    """The wheel net without the left turn from a-e into e-d: the trust-free route to e-d goes round,
    and SUMO's route of the ego is the roads' edge lists, with no detour in between."""
    net = build_plain_net(tmp_path, "left", WHEEL_NODES, WHEEL_ROADS, forbidden=[("a_e", "e_d")])
    import_town(net, tmp_path / "town.json")
    (tmp_path / "spec.toml").write_text('name = "left"\nstart = "b-a"\nformula = "F v1"\n\n'
                                        '[states]\nv1 = ["e-d"]\n')
    town = load_town(tmp_path / "town.json")
    assert town.actions("a-e") == ("b", "c")
    without_turns = json.loads((tmp_path / "town.json").read_text())
    del without_turns["turns"]
    assert town_from_dict(without_turns).shortest_route("b-a", ["e-d"]) == ["b-a", "a-e", "e-d"]
    record, watcher = drive(town, load_spec(str(tmp_path / "spec.toml"), town), load_driver_model(None), 1)
    route = record.roads["directed_road"].tolist()
    assert record.summary["end_reason"] == "accepted" and route[-1] == "e-d"
    assert all(b.split("-")[1] in town.actions(a) for a, b in zip(route, route[1:], strict=False))
    check_route(town, record, watcher)


def test_an_oncoming_truck_comes_only_from_lanes_open_to_trucks(tmp_path):
    """The wheel's DRT net, incident seed 1: a truck scene on the route from 1652675108-2648328514
    would start its truck on -24733697#0, which only buses, delivery vehicles, bicycles and
    pedestrians may use; SUMO refuses a truck there, and the episode stopped with an error. The
    truck comes from a lane open to trucks instead, and every truck drives only such lanes."""
    from benchmarks.bench_episode import route_through_every_kind
    from trustroute.policies.routing.fixed_route import FixedRoute

    net = Path(sumo.SUMO_HOME) / "tools" / "game" / "DRT" / "osm.net.xml"
    town = import_town(net, tmp_path / "drt.json", rng=np.random.default_rng(1), incident_seed=1).town
    start = "1652675108-2648328514"
    route = route_through_every_kind(town, start)
    (tmp_path / "spec.toml").write_text(f'name = "drt"\nstart = "{start}"\nformula = "F v1"\n\n'
                                        f'[states]\nv1 = ["{route[-1]}"]\n')
    town = load_town(tmp_path / "drt.json")
    model = load_driver_model(None)
    truck_lanes: set[str] = set()
    closed: set[str] = set()

    def observe(sumo, ego, mode, road):
        for vehicle in sumo.vehicle.getIDList():
            if vehicle.endswith((".truck", ".oncoming")):
                lane = sumo.vehicle.getLaneID(vehicle)
                truck_lanes.add(lane)
                if "truck" in sumo.lane.getDisallowed(lane):
                    closed.add(lane)

    setup = EpisodeSetup(town=town, driver_model=model, spec=load_spec(str(tmp_path / "spec.toml"), town),
                         fallback_after=None)
    record = run_episode(setup, FixedRoute(route), SyntheticDriver(model, np.random.default_rng(1)), "drt", 1,
                         EpisodeOptions(observer=observe))
    assert record.summary["end_reason"] == "accepted"
    incidents = record.incidents
    trucks = incidents[(incidents["incident"] == "truck") & incidents["sumo_ids"].notna()]
    assert len(trucks) >= 1 and truck_lanes
    assert closed == set()


def test_a_given_net_that_is_missing_or_unreadable_is_an_input_error(city, tmp_path):
    """A net passed for an imported town (the API's `net`, the gym env's `net_path`) is checked
    before sumolib reads it: a missing or broken file is an InputError naming it, not sumolib's
    ValueError or XML parser error."""
    town = load_town(city["town"])
    model = load_driver_model(None)
    spec = load_spec(str(city["spec"]), town)
    policy = resolve_policy("free", town, model, spec, None)
    setup = EpisodeSetup(town=town, driver_model=model, spec=spec)
    broken = tmp_path / "broken.net.xml"
    broken.write_text("<net><edge")
    for net, words in ((tmp_path / "missing.net.xml", "does not exist"), (broken, "not a readable SUMO net")):
        with pytest.raises(InputError, match=words) as raised:
            run_episode(setup, policy, SyntheticDriver(model, np.random.default_rng(0)), "e0", 0,
                        EpisodeOptions(net_path=net))
        assert str(net) in str(raised.value)
