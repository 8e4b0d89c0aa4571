"""The packaged town `city`: sumo-rl's RESCO Ingolstadt net imported on first use into the cache,
once per content of the scenario, with at least 200 junctions; without the `cities` extra every
command that names it says so in one line with the fix, exit code 2. The packaged town `csomor`:
built with netconvert from the packaged plain XML and imported on first use, once per content, with
its choice junctions checked against an independent count from sumolib on the built net."""

from __future__ import annotations

import gzip
import importlib.util
import shutil
from pathlib import Path

import pytest
import sumolib

from tests.cli import run_cli
from tests.extras import needs_cities_extra
from trustroute.core.packaged import SPEC_TOWNS, packaged_spec_names
from trustroute.networks import cities
from trustroute.networks.real_net import town_net_file
from trustroute.networks.road import Road
from trustroute.networks.road_geometry import file_sha256
from trustroute.networks.road_lookup import choice_junctions
from trustroute.networks.town import TOWNS, load_town


@needs_cities_extra
def test_city_is_imported_once_into_the_cache_with_its_net_and_demand():
    folder = cities.city_folder()
    town_file = folder / cities.CITY_TOWN_FILE
    written = town_file.stat().st_mtime_ns
    assert cities.city_folder() == folder and town_file.stat().st_mtime_ns == written   # not imported again
    assert TOWNS.resolve("city") == town_file and cities.ROUTES.resolve("city") == cities.city_routes_path()
    net, routes = cities.scenario_files()
    town = load_town("city")
    # a city's size (the roads the net's turns let a car drive to and from each other); the net
    # beside the town is the scenario's, checked by its hash
    assert len(town.junctions) >= 200 and len(town.states) > 500
    assert town_net_file(town) == folder / net.name and file_sha256(folder / net.name) == file_sha256(net)
    assert (folder / routes.name).read_bytes() == routes.read_bytes()
    assert f"seed {cities.CITY_INCIDENT_SEED}" in town.provenance
    assert {kind for kind in town.incidents.values()} == {"none", "obstacle", "truck", "pedestrian"}


@needs_cities_extra
def test_another_scenario_content_is_another_town(tmp_path, monkeypatch):
    net, routes = cities.scenario_files()
    changed = tmp_path / routes.name
    shutil.copyfile(routes, changed)
    changed.write_text(changed.read_text().replace("</routes>", "<!-- one more line -->\n</routes>"))
    first = cities.city_folder()
    monkeypatch.setattr(cities, "scenario_files", lambda: (net, changed))
    second = cities.city_folder()
    assert second != first and second.parent == first.parent
    assert (second / cities.CITY_TOWN_FILE).read_bytes() == (first / cities.CITY_TOWN_FILE).read_bytes()
    assert not [p for p in first.parent.iterdir() if p.name.startswith(".")]   # no work folder left


def _without_sumo_rl(monkeypatch, location: Path | None = None) -> None:
    real = importlib.util.find_spec

    def find_spec(name, *args):
        if name != "sumo_rl":
            return real(name, *args)
        if location is None:
            return None
        return importlib.util.spec_from_file_location("sumo_rl", location / "__init__.py",
                                                      submodule_search_locations=[str(location)])

    monkeypatch.setattr(importlib.util, "find_spec", find_spec)


@pytest.mark.parametrize("args", [
    ["spec", "check", "city5", "--town", "city"],
    ["evaluate", "city5", "free", "--town", "city"],
    ["run", "phi1", "--routes", "city"],
])
def test_without_the_extra_the_city_is_one_line_naming_the_fix(capsys, monkeypatch, args):
    _without_sumo_rl(monkeypatch)
    code, out, err = run_cli(capsys, *args)
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "sumo-rl" in err and "pip install 'trustroute[cities]'" in err


def test_a_sumo_rl_without_the_scenario_is_one_line_too(capsys, monkeypatch, tmp_path):
    _without_sumo_rl(monkeypatch, tmp_path / "sumo_rl")
    code, out, err = run_cli(capsys, "synth", "city5", "--town", "city", "--horizon", "3")
    assert code == 2 and err.count("\n") == 1 and "lacks the RESCO Ingolstadt scenario" in err, err
    assert "pip install 'trustroute[cities]'" in err


@needs_cities_extra
@pytest.mark.parametrize("town", [[], ["--town", "pentagon"]], ids=["default town", "pentagon"])
def test_the_city_routes_on_another_town_name_the_town_they_need(capsys, town):
    code, out, err = run_cli(capsys, "run", "phi1", "--routes", "city", *town)
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "--routes: the packaged route set 'city' is traffic on the town city's roads" in err
    assert "(fix: add --town city, or drop --routes city)" in err


@needs_cities_extra
def test_a_study_config_takes_the_city_routes_with_the_city_only(tmp_path):
    from trustroute.core.errors import InputError
    from trustroute.harness.study.config import load_study_config

    config = tmp_path / "s.toml"
    text = ('[study]\nparticipants = 1\nseed = 1\nspecs = ["city5"]\nconditions = ["free"]\n'
            'routes = ["city"]\n')
    config.write_text(text + 'town = "city"\n')
    assert load_study_config(config).routes == (str(cities.city_routes_path().resolve()),)
    config.write_text(text)
    with pytest.raises(InputError) as error:
        load_study_config(config)
    assert error.value.place == "study.routes"
    assert error.value.fix == 'set town = "city", or drop "city" from routes'


def test_the_city_specs_are_packaged_for_their_city_only():
    assert "city" in TOWNS.names() and "city" in cities.ROUTES.names()
    assert "csomor" in TOWNS.names() and "csomor" not in cities.ROUTES.names()
    assert SPEC_TOWNS == {"city5": "city", "csomor5": "csomor"}
    assert packaged_spec_names("city") == ["city5"] and "city5" not in packaged_spec_names()
    assert packaged_spec_names("csomor") == ["csomor5"] and "csomor5" not in packaged_spec_names()
    assert "phi1" in packaged_spec_names()


def test_csomor_is_built_once_into_the_cache_from_the_packaged_plain_xml():
    folder = cities.csomor_folder()
    town_file = folder / cities.CSOMOR_TOWN_FILE
    written = town_file.stat().st_mtime_ns
    assert cities.csomor_folder() == folder and town_file.stat().st_mtime_ns == written   # not built again
    assert TOWNS.resolve("csomor") == town_file
    assert sorted(p.name for p in folder.iterdir()) == [cities.CSOMOR_TOWN_FILE, cities.CSOMOR_NET_FILE]
    town = load_town("csomor")
    assert town_net_file(town) == folder / cities.CSOMOR_NET_FILE
    assert len(town.junctions) == 601 and len(town.states) == 1648
    assert f"seed {cities.CITY_INCIDENT_SEED}" in town.provenance
    assert {kind for kind in town.incidents.values()} == {"none", "obstacle", "truck", "pedestrian"}
    # the packaged data carries its licence and provenance beside the plain files
    assert {p.name for p in cities.CSOMOR_DATA.iterdir()} >= {"README.md", "LICENSE-routerl.txt"}


def test_other_plain_xml_is_another_csomor_and_a_broken_one_is_one_line(tmp_path, monkeypatch, capsys):
    first = cities.csomor_folder()
    plain = cities.csomor_plain_files()
    changed = dict(plain, typ=tmp_path / "csomor.typ.xml.gz")
    changed["typ"].write_bytes(gzip.compress(gzip.decompress(plain["typ"].read_bytes()) + b"<!-- -->\n"))
    monkeypatch.setattr(cities, "csomor_plain_files", lambda: changed)
    second = cities.csomor_folder()
    assert second != first and second.parent == first.parent
    assert (second / cities.CSOMOR_TOWN_FILE).read_bytes() == (first / cities.CSOMOR_TOWN_FILE).read_bytes()
    shutil.rmtree(second)
    broken = dict(plain, edg=tmp_path / "csomor.edg.xml.gz")
    broken["edg"].write_bytes(gzip.compress(b"<edges><edge id='x' from='nowhere' to='nada'/></edges>"))
    monkeypatch.setattr(cities, "csomor_plain_files", lambda: broken)
    code, out, err = run_cli(capsys, "spec", "check", "csomor5", "--town", "csomor")
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "netconvert could not build the net of Csömör" in err
    assert not [p for p in first.parent.iterdir() if p.name.startswith(".")]   # no work folder left


def _sumolib_choice_junctions(net_path: Path, driven: set[str]) -> set[str]:
    """Junctions of the net where a car arriving on an edge the town drives has two or more driven
    next edges that do not lead straight back to the junction it came from, read from sumolib's
    node objects."""
    net = sumolib.net.readNet(str(net_path))
    found = set()
    for node in net.getNodes():
        outgoing = [e for e in node.getOutgoing() if e.getID() in driven]
        for edge in node.getIncoming():
            if edge.getID() in driven and len({o.getToNode().getID() for o in outgoing
                                               if o.getToNode() != edge.getFromNode()}) >= 2:
                found.add(node.getID())
    return found


def test_csomor_choice_junctions_against_an_independent_count_from_sumolib():
    town = load_town("csomor")
    model = choice_junctions(town)
    assert len(model) == 481 >= 200   # docs/cities.md; the scale target asks for 200
    net = sumolib.net.readNet(str(town_net_file(town)))
    assert set(town.junctions) <= {node.getID() for node in net.getNodes()}
    driven = {edge for geometry in town.geometry.values() for edge in geometry.edges}
    net_count = _sumolib_choice_junctions(town_net_file(town), driven)
    assert model <= net_count and len(net_count - model) == 4
    for junction in net_count - model:
        # The net's extra choice is the model's road back to the junction the car came from, by
        # another way than the edge it arrived on (a loop of one-way edges): the model's U-turn.
        loops = []
        for road in (r for r in town.states if Road.parse(r).to_junction == junction):
            came_from = Road.parse(road).from_junction
            back = town.geometry.get(f"{junction}-{came_from}")
            arrived = net.getEdge(town.geometry[road].edges[-1])
            if back is not None and net.getEdge(back.edges[0]).getToNode() != arrived.getFromNode():
                loops.append(road)
        assert loops, junction
