"""`trustroute town import`: the written town loads and is the same bytes twice, specs and the
baseline accept it, incidents come from a file or the seeded rule, bad input is one line with exit
code 2 and no file, and the eclipse-sumo wheel's own nets import."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import sumo

from tests.cli import run_cli
from tests.networks.sumo_nets import WHEEL_NODES, WHEEL_ROADS, build_plain_net
from trustroute.core.errors import InputError
from trustroute.networks.road_geometry import check_sumo_net, file_sha256
from trustroute.networks.town import NO_INCIDENT, load_town
from trustroute.networks.town_import import import_town
from trustroute.networks.town_incidents import RoadFacts, draw_incidents

GAME = Path(sumo.SUMO_HOME) / "tools" / "game"
CITY_NETS = ["DRT/osm.net.xml", "A10KW/osm.net.xml", "bs3d/bs.net.xml",
             "fokr_bs_demo/fokr_bs.net.xml.gz", "grid6/grid6.net.xml"]


@pytest.fixture()
def wheel(tmp_path) -> Path:
    one_way = [("b", "c")]
    return build_plain_net(tmp_path, "wheel", WHEEL_NODES, [r for r in WHEEL_ROADS if r != ("b", "c")],
                           one_way=one_way)


def test_import_writes_a_town_that_loads(wheel, tmp_path, capsys):
    code, out, err = run_cli(capsys, "town", "import", str(wheel), "--out", str(tmp_path / "town.json"))
    assert code == 0, err
    assert out.splitlines()[0] == str(tmp_path / "town.json")
    assert len(err.splitlines()) == 1 and "dropped nothing" in err
    town = load_town(tmp_path / "town.json")
    assert town.one_way == frozenset({("b", "c")}) and "c-b" not in town.states
    assert len(town.states) == 15 and set(town.incidents.values()) == {NO_INCIDENT}
    assert town.sumo_net is not None and town.sumo_net.file == "wheel.net.xml"
    assert check_sumo_net(town.sumo_net, town.source_path) == wheel
    for road in town.states:
        assert town.length(road) == town.geometry[road].length
    assert town.successors("a-b") == ("b-c", "b-e")  # the one-way street is taken from b only


def test_import_twice_gives_the_same_bytes(wheel, tmp_path, capsys):
    for name in ("one.json", "two.json"):
        code, _, err = run_cli(capsys, "town", "import", str(wheel), "--out", str(tmp_path / name),
                               "--incident-seed", "7", "--quiet")
        assert code == 0 and err == ""
    assert (tmp_path / "one.json").read_bytes() == (tmp_path / "two.json").read_bytes()
    code, out, err = run_cli(capsys, "town", "import", str(wheel), "--out", str(tmp_path / "three.json"),
                             "--incident-seed", "7", "--json")
    assert code == 0 and err == ""
    summary = json.loads(out)
    assert summary["paths"] == {"town": str(tmp_path / "three.json"), "net": str(wheel)}
    assert (summary["junctions"], summary["roads"], summary["one_way_roads"]) == (5, 15, 1)
    assert summary["content_hash"] == load_town(tmp_path / "one.json").content_hash


def test_spec_check_and_baseline_accept_a_spec_on_the_imported_town(wheel, tmp_path, capsys):
    town_path = tmp_path / "town.json"
    import_town(wheel, town_path)
    spec = tmp_path / "spec.toml"
    spec.write_text('name = "wheel"\nstart = "a-b"\nformula = "F (v1 & F v2)"\n\n[states]\n'
                    'v1 = ["b-c"]\nv2 = ["d-a"]\n')
    code, out, err = run_cli(capsys, "spec", "check", str(spec), "--town", str(town_path), "--json")
    assert code == 0, err
    assert json.loads(out)["name"] == "wheel"
    code, out, err = run_cli(capsys, "baseline", str(spec), "--town", str(town_path), "--json")
    assert code == 0, err
    route = json.loads(out)["route"]
    assert route[0] == "a-b" and "b-c" in route and route[-1] == "d-a"


def test_incidents_from_a_file_by_road_or_edge(wheel, tmp_path):
    incidents = tmp_path / "incidents.json"
    incidents.write_text(json.dumps({"a-b": "truck", "c_d": "pedestrian"}))
    town = import_town(wheel, tmp_path / "town.json", incidents_path=str(incidents)).town
    assert town.incident("a-b") == "truck" and town.incident("c-d") == "pedestrian"
    assert sum(kind != NO_INCIDENT for kind in town.incidents.values()) == 2
    incidents.write_text(json.dumps({"nowhere": "truck"}))
    with pytest.raises(InputError, match="neither a road"):
        import_town(wheel, tmp_path / "other.json", incidents_path=str(incidents))
    assert not (tmp_path / "other.json").exists()


def test_incident_rule_is_seeded_and_follows_length_and_class():
    roads = [RoadFacts(f"r{i}-s{i}", length=float(length), speed=speed)
             for i, (length, speed) in enumerate([(50, 8.0), (3000, 8.0), (3000, 30.0)] * 400)]
    first = draw_incidents(roads, np.random.default_rng(1))
    assert first == draw_incidents(roads, np.random.default_rng(1))
    assert first != draw_incidents(roads, np.random.default_rng(2))

    def share(index: int, kind: str | None = None) -> float:
        picked = [first[r.name] for r in roads[index::3]]
        return np.mean([k != NO_INCIDENT if kind is None else k == kind for k in picked])

    assert share(0) < 0.3 < 0.9 < share(1)  # about 1 - exp(-length / 500 m)
    assert share(1, "pedestrian") > share(1, "truck") and share(2, "truck") > share(2, "pedestrian")


def test_incident_options_exclude_each_other(wheel, tmp_path, capsys):
    code, _, err = run_cli(capsys, "town", "import", str(wheel), "--out", str(tmp_path / "t.json"),
                           "--incident-seed", "1", "--incidents", str(tmp_path / "i.json"))
    assert code == 2 and "not both" in err and not (tmp_path / "t.json").exists()


@pytest.mark.parametrize("case", ["no_passenger", "disconnected", "bad_osm", "nan_shape", "suffix",
                                  "routes_file"])
def test_bad_input_is_one_line_exit_2_and_no_town(case, tmp_path, capsys):
    out = tmp_path / "town.json"
    out.write_text("the town before")
    if case == "no_passenger":
        source = build_plain_net(tmp_path, "rail", WHEEL_NODES, WHEEL_ROADS,
                                 allow={(u, v): "rail" for a, b in WHEEL_ROADS for u, v in ((a, b), (b, a))})
        expected = "no road a passenger car may use"
    elif case == "disconnected":
        source = build_plain_net(tmp_path, "line", WHEEL_NODES, [], one_way=[("a", "b"), ("b", "c")])
        expected = "nothing strongly connected"
    elif case == "bad_osm":
        source = tmp_path / "bad.osm"
        source.write_text("<osm><node id='1' lat='x'/></osm>")
        expected = "netconvert rejected the OpenStreetMap file"
    elif case == "nan_shape":
        net = build_plain_net(tmp_path, "wheel", WHEEL_NODES, WHEEL_ROADS).read_text()
        source = tmp_path / "nan.net.xml"
        lane = re.search(r'<lane id="a_b_0"[^>]*shape="', net)
        assert lane is not None
        source.write_text(net[:lane.end()] + "nan,nan " + net[lane.end():])
        expected = "not finite"
    elif case == "routes_file":   # a route file named as a net: sumolib reads it as an empty net
        source = tmp_path / "demand.net.xml"
        source.write_text('<routes><vehicle id="v" depart="0"/></routes>\n')
        expected = "holds no SUMO net (no junction, no edge)"
    else:
        source = tmp_path / "town.txt"
        source.write_text("x")
        expected = "not a SUMO net or an OpenStreetMap file"
    code, stdout, err = run_cli(capsys, "town", "import", str(source), "--out", str(out))
    assert code == 2 and stdout == ""
    assert len(err.splitlines()) == 1 and expected in err and str(source) in err and "fix:" in err
    assert out.read_text() == "the town before"
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".tmp")) == []


@pytest.mark.parametrize("net", CITY_NETS)
def test_the_wheel_nets_import(net, tmp_path):
    result = import_town(GAME / net, tmp_path / "town.json", rng=np.random.default_rng(0), incident_seed=0)
    town = load_town(tmp_path / "town.json")
    assert town.content_hash == result.town.content_hash
    assert len(town.junctions) >= 5 and len(town.states) >= 8
    assert town.sumo_net is not None and town.sumo_net.sha256 == file_sha256(GAME / net)
    # every road can be left (the graph is strongly connected), and lengths are the edges' sums
    assert all(town.successors(road) for road in town.states)
    assert all(town.length(road) > 0 for road in town.states)


@pytest.mark.parametrize("net", ["fkk_in/ingolstadt.net.xml.gz", "cross/cross.net.xml"])
def test_a_net_whose_turns_lead_out_of_it_is_refused(net, tmp_path, capsys):
    """fkk_in's Ingolstadt cut-out and the single crossing: their junctions are strongly connected
    by edges, but every way a car may turn leads off the net or into a dead end without a
    turnaround."""
    source = GAME / net
    code, stdout, err = run_cli(capsys, "town", "import", str(source), "--out", str(tmp_path / "t.json"))
    assert code == 2 and stdout == "" and len(err.splitlines()) == 1
    assert "no two roads that can be driven to and from each other" in err and str(source) in err
    assert not (tmp_path / "t.json").exists()


def test_the_wheel_osm_extract_imports_the_same_twice(tmp_path, capsys):
    source = GAME / "racing" / "spreewaldring.osm"
    for name in ("one", "two"):
        code, _, err = run_cli(capsys, "town", "import", str(source), "--out", str(tmp_path / f"{name}.json"))
        assert code == 0, err
    assert (tmp_path / "one.net.xml").read_bytes() == (tmp_path / "two.net.xml").read_bytes()
    one = json.loads((tmp_path / "one.json").read_text())
    assert one["sumo_net"]["file"] == "one.net.xml"
    assert one["sumo_net"]["sha256"] == file_sha256(tmp_path / "one.net.xml")
    town = load_town(tmp_path / "one.json")
    assert len(town.junctions) >= 2 and town.states


def test_a_missing_net_or_a_folder_is_named_as_such(tmp_path, capsys):
    """A net that is not there is "does not exist", a folder "is not a file", before sumolib is asked
    (which reports a missing file as an unknown URL type)."""
    (tmp_path / "folder.net.xml").mkdir()
    for path, words in ((tmp_path / "nofile.net.xml", "file does not exist"),
                        (tmp_path / "folder.net.xml", "path is not a file")):
        code, _, err = run_cli(capsys, "town", "import", str(path), "--out", str(tmp_path / "t.json"))
        assert code == 2 and err.count("\n") == 1, err
        assert f"{path}: the SUMO net {words}" in err and "url" not in err.lower()
    assert not (tmp_path / "t.json").exists()
