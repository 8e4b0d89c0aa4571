"""The packaged town `city`: sumo-rl's RESCO Ingolstadt net imported on first use into the cache,
once per content of the scenario, with at least 200 junctions; without the `cities` extra every
command that names it says so in one line with the fix, exit code 2."""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import pytest

from tests.cli import run_cli
from trustroute.core.packaged import SPEC_TOWNS, packaged_spec_names
from trustroute.networks import cities
from trustroute.networks.real_net import town_net_file
from trustroute.networks.road_geometry import file_sha256
from trustroute.networks.town import TOWNS, load_town

needs_extra = pytest.mark.skipif(importlib.util.find_spec("sumo_rl") is None,
                                 reason="needs the optional extra: pip install -e '.[cities]'")


@needs_extra
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


@needs_extra
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


def test_the_city_spec_is_packaged_for_the_city_only():
    assert "city" in TOWNS.names() and "city" in cities.ROUTES.names()
    assert SPEC_TOWNS == {"city5": "city"}
    assert packaged_spec_names("city") == ["city5"] and "city5" not in packaged_spec_names()
    assert "phi1" in packaged_spec_names()
