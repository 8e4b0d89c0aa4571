"""Towns as the commands see them: the trust POMDP of a town and a driver model, the town's SUMO
net built, towns imported from SUMO nets and OpenStreetMap maps, and a town's roads found by place
or street (`trustroute model`, `net build`, `town import`, `town roads`)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from trustroute.app.inputs import driver_of, town_of
from trustroute.app.nets import net_for
from trustroute.core.errors import InputError
from trustroute.networks.cities import ROUTES, check_route_set_town, read_route_file
from trustroute.networks.real_net import is_imported
from trustroute.networks.road_lookup import RoadRow, road_rows, street_names
from trustroute.networks.sumo_net import NetBuild, build_net, net_counts
from trustroute.networks.town import Town
from trustroute.networks.town_import import TownImport, import_town
from trustroute.policies.model.trust_pomdp import build_pomdp


def model_summary(town_path: str | None, driver_path: str | None) -> dict:
    """The trust POMDP of a town and a driver model (`trustroute model`), JSON-ready."""
    town = town_of(town_path)
    driver = driver_of(driver_path)
    pomdp = build_pomdp(town, driver)
    incidents = {}
    for kind in driver.incident_types:
        incidents[kind] = sum(1 for v in town.incidents.values() if v == kind)
    return {
        "town": town.source_path,
        "town_hash": town.content_hash[:12],
        "junctions": len(town.junctions),
        "roads": len(town.roads),
        "one_way_roads": len(town.one_way),
        "states": pomdp.n_states,
        "incidents_per_type": incidents,
        "trust_levels": list(driver.trust_levels),
        "driver_model": driver.source_path,
        "driver_hash": driver.content_hash[:12],
        "performance_dependent": driver.depends_on_performance,
        "initial_belief": np.round(driver.initial_belief, 4).tolist(),
        "takeover_probability": {
            kind: np.round(driver.takeover_probability[i], 3).tolist()
            for i, kind in enumerate(driver.incident_types)
        },
    }


def build_town_net(town_path: str | None, out_dir: str | None = None) -> NetBuild:
    """The SUMO net the town drives: built from its junctions and roads (cached by its content
    hash), or, for a town imported from a net, that net itself (`net_for`; nothing is built)."""
    town = town_of(town_path)
    if not is_imported(town):
        return build_net(town, Path(out_dir) if out_dir else None)
    if out_dir is not None:
        raise InputError("--out", "", f"the town {town.source_path} drives the net it was imported from; "
                         "nothing is built", "drop --out (the town's net is printed)")
    started = time.perf_counter()
    path = net_for(town)
    return NetBuild(path=path, cached=True, seconds=time.perf_counter() - started, **net_counts(path))


def import_town_file(source: str, out: str, incidents_path: str | None, incident_seed: int | None,
                     net_out: str | None) -> TownImport:
    """Import a SUMO net or an OSM map as a town file at `out` (incidents from a file, drawn by
    the seeded rule, or none)."""
    rng = np.random.default_rng(incident_seed) if incident_seed is not None else None
    return import_town(source, out, incidents_path=incidents_path, rng=rng, net_out=net_out,
                       incident_seed=incident_seed)


def town_roads(town_path: str, near: tuple[float, float] | None, street: str | None,
               limit: int | None) -> tuple[str, list[RoadRow]]:
    """(the town's file, its directed roads near a point or on a street, at most `limit`)."""
    town = town_of(town_path, given="TOWN")
    if limit is None and near is not None:
        limit = 10
    rows = road_rows(town, near=near, street=street, limit=limit)
    if street is not None and not rows:
        known = street_names(town)
        raise InputError(town_path, "--street", f"no road is on a street named '{street}'",
                         f"use one of the town's {len(known)} street names (e.g. {', '.join(known[:3])})"
                         if known else "this town's roads carry no street names (import a town from a net "
                         "with names: trustroute town import)")
    return town.source_path, rows


def check_routes_town(paths: tuple[str, ...], town: Town) -> None:
    """The packaged route sets among --routes are traffic on `town`'s roads (networks/cities.py)."""
    for path in paths:
        check_route_set_town(path, ROUTES.resolve(path), town, path, "--routes",
                             f"add --town {{town}}, or drop --routes {path}")


def route_file(path: str) -> str:
    """A background route file (a path, or a packaged name: `city`, the city's own demand), read and
    parsed once to fail early with one line (absolute: SUMO resolves it)."""
    path = str(ROUTES.resolve(path))
    if not Path(path).exists():
        raise InputError(path, "", "no such SUMO route file", "pass an existing .rou.xml file or a "
                         f"packaged route name ({', '.join(ROUTES.names())})")
    read_route_file(path)
    return str(Path(path).resolve())
