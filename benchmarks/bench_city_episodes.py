"""Episodes on a real city with background traffic: how the per-episode wall time grows with the
number of vehicles, against a bare libsumo run of the same net and demand measured in the same run.

The city is the packaged town `city`: sumo-rl's RESCO Ingolstadt scenario (the `cities` extra; 381
SUMO junctions) as the package imports it (networks/cities.py, into the cache, again whenever the
importer's code changes). The ego drives the trust-free policy of a two-waypoint spec (`SPEC`, 22
roads and 1.8 km); the demand levels are none,
SUMO's randomTrips.py at TRIP_RATES trips per minute (one seeded trips file per rate, written
before the clock) and the scenario's own routes (about 71 vehicles per minute, shifted to start
with the episode). The episode gets the demand as route files (`SumoConfig.route_files`), as
`trustroute run --routes` does; the bare run starts SUMO with the same command line and the same
files, inserts the ego with the whole route of edges the episode drove (its roads' edges, SUMO's
shortest way where the net has no turn between two roads) at the same place, and steps until it
arrives: no policy, tracker, driver, incidents or logging. Episodes and bare runs each run in a
process of their own (benchmarks/timing.py TimingProcess). Per level: the median of PAIRS
interleaved (episode, bare) pairs of wall times and their ratio, the vehicles on the net (mean
and largest, counted in an extra bare run), sim seconds of both, and the 1-minute load average.

`python -m benchmarks.bench_city_episodes [PAIRS]` prints the rows as a Markdown table as well.
"""

from __future__ import annotations

import importlib.util
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.timing import TimingProcess, paired_timings
from trustroute.harness.simulation.background import random_trips, shifted_routes
from trustroute.harness.simulation.episode import (
    COMMIT_DISTANCE,
    START_BEFORE_COMMIT,
    EpisodeOptions,
    run_episode,
)
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.real_roads import RealRoads
from trustroute.harness.simulation.sumo_start import SumoConfig, fresh_session
from trustroute.networks.cities import CITY, city_routes_path
from trustroute.networks.real_net import road_edges, town_net_file
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import trust_free_policy

SEED = 3
PAIRS = 7
TRIP_RATES = (10, 30, 60, 120)   # randomTrips.py trips per minute
BARE_LIMIT = 3600.0              # sim seconds: a bare run whose ego is locked in a jam stops here
SPEC = """name = "ingolstadt"
start = "2068408769-89173763"
formula = "F (v1 & F v2)"

[states]
v1 = { junction = "267783873" }
v2 = { junction = "30624898" }
"""


def city_spec(town, folder: Path):
    """`SPEC` on the packaged city, written to `folder` and loaded as a spec file is."""
    path = folder / "spec.toml"
    path.write_text(SPEC)
    return load_spec(str(path), town)


def bare_route(sumo, roads: dict, route: list[str]) -> list[str]:
    """The roads' edges one after another, SUMO's shortest way between two roads the net does not
    connect (as the episode drives them)."""
    edges: list[str] = list(roads[route[0]].ids)
    for road, nxt in zip(route, route[1:], strict=False):
        last, first = roads[road].edges[-1], roads[nxt].ids[0]
        if first not in last.successors:
            edges += list(sumo.simulation.findRoute(last.edge, first).edges)[1:-1]
        edges += list(roads[nxt].ids)
    return edges


def bare_run(net: Path, roads: dict, route: list[str], config: SumoConfig,
             count: list[int] | None = None) -> float:
    """The ego alone with the demand of `config`: returns the sim seconds until it arrives; appends
    the number of vehicles on the net at every step to `count` when given (not while timed)."""
    real = RealRoads(roads, COMMIT_DISTANCE)
    with fresh_session(net, SEED, config) as sumo:
        start = route[0]
        ahead = max(0.0, real.length(start) - COMMIT_DISTANCE - START_BEFORE_COMMIT)
        first, depart = real.start(start, ahead)
        # from the start road's edge the episode's ego departs on, as the episode's first route
        sumo.route.add("r", first + bare_route(sumo, roads, route)[len(roads[start].ids):])
        sumo.vehicle.add("ego", "r", depart="now", departLane="best", departPos=f"{depart:.2f}",
                         departSpeed="max")
        sumo.vehicle.subscribe("ego", [sumo.VAR_ROAD_ID])
        seen = False
        while True:
            sumo.simulationStep()
            if count is not None:
                count.append(sumo.vehicle.getIDCount())
            if sumo.vehicle.getSubscriptionResults("ego"):
                seen = True
            elif seen or sumo.simulation.getTime() > BARE_LIMIT:
                return sumo.simulation.getTime()


def demand_levels(net: Path, scenario_routes: Path, folder: Path) -> list[tuple[str, tuple[str, ...], dict]]:
    """(name, route files, details) per level of demand, files written before any clock starts."""
    levels: list[tuple[str, tuple[str, ...], dict]] = [("none", (), {})]
    for rate in TRIP_RATES:
        sub = folder / f"trips{rate}"
        sub.mkdir()
        started = time.perf_counter()
        trips = random_trips(net, SEED, rate, sub)
        levels.append((f"random_trips_{rate}_per_min", (str(trips),),
                       {"trips_per_minute": rate, "random_trips_seconds": time.perf_counter() - started}))
    scenario_files = shifted_routes((str(scenario_routes),), folder)
    levels.append(("scenario_demand", scenario_files, {"trips_per_minute": 4283 / 60.0}))
    return levels


def run(pairs: int = PAIRS) -> list[dict]:
    if importlib.util.find_spec("sumo_rl") is None:
        return [{"name": "city_episodes", "skipped": "sumo-rl (the cities extra) is not installed"}]
    town = load_town(CITY)
    model = load_driver_model()
    net = town_net_file(town)
    roads = road_edges(town, net)
    rows = []
    with tempfile.TemporaryDirectory(prefix="trustroute-city-bench-") as folder:
        spec = city_spec(town, Path(folder))
        setup = EpisodeSetup(town=town, driver_model=model, spec=spec)
        policy = trust_free_policy(town, spec)
        for name, files, details in demand_levels(net, city_routes_path(), Path(folder)):
            config = replace(SumoConfig(), route_files=files)

            def episode(config=config):
                driver = SyntheticDriver(model, np.random.default_rng(SEED))
                record = run_episode(setup, policy, driver, "city", SEED, EpisodeOptions(config=config))
                record.tables()
                return record

            record = episode()   # warm, and the route the bare run drives
            route = record.roads["directed_road"].tolist()
            vehicles: list[int] = []
            bare_sim = bare_run(net, roads, route, config, vehicles)

            def bare(config=config, route=route):
                return bare_run(net, roads, route, config)

            # each in a process of its own: the bare run starts and closes SUMO, the episodes keep
            # theirs open where they may (sumo_start.reusable: the level without route files)
            with TimingProcess(episode) as timed_episode, TimingProcess(bare) as timed_bare:
                paired = paired_timings(timed_episode, timed_bare, pairs=pairs)
            rows.append({
                "name": f"city_episode_wall.{name}", "value": paired["target_wall_median"], "unit": "s",
                "baseline": paired["baseline_wall_median"], "ratio": paired["wall_ratio_median"],
                "cpu_ratio": paired["cpu_ratio_median"],
                "ratio_what": f"median of {pairs} interleaved (episode, bare libsumo) pairs",
                **{key: value for key, value in paired.items() if not key.endswith("ratio_median")},
                "vehicles_mean": float(np.mean(vehicles)), "vehicles_max": int(np.max(vehicles)),
                "sim_seconds": record.summary["sim_seconds"], "bare_sim_seconds": bare_sim,
                "roads": len(route), "end_reason": record.summary["end_reason"],
                "policy": "free (trust-free)", "town_junctions": len(town.junctions),
                "load_average_1min_now": os.getloadavg()[0], **details,
                # traffic and incidents make the episode longer in sim time than the bare run
                "ratio_per_sim_second": (paired["wall_ratio_median"] * bare_sim
                                         / record.summary["sim_seconds"]),
            })
    return [*rows, growth(rows)]


def growth(rows: list[dict]) -> dict:
    """Least-squares lines of the median episode and bare times (wall and CPU) against the mean
    number of vehicles on the net, over the demand levels: seconds per episode per vehicle."""
    vehicles = np.array([row["vehicles_mean"] for row in rows])
    out = {"name": "city_episode_seconds_per_vehicle", "unit": "s per vehicle on the net",
           "levels": len(rows), "load_average_1min": [rows[0]["load_average_1min"][0],
                                                      rows[-1]["load_average_1min"][1]]}
    for key, column in (("episode_wall", "target_wall_median"), ("bare_wall", "baseline_wall_median"),
                        ("episode_cpu", "target_cpu_median"), ("bare_cpu", "baseline_cpu_median")):
        slope, intercept = np.polyfit(vehicles, [row[column] for row in rows], 1)
        out[key] = {"per_vehicle": float(slope), "at_no_vehicles": float(intercept)}
    out["value"] = out["episode_wall"]["per_vehicle"]
    out["ratio"] = out["episode_wall"]["per_vehicle"] / out["bare_wall"]["per_vehicle"]
    out["cpu_ratio"] = out["episode_cpu"]["per_vehicle"] / out["bare_cpu"]["per_vehicle"]
    return out


def markdown(rows: list[dict]) -> str:
    lines = ["| demand | vehicles on the net (mean / max) | episode wall (median) | bare libsumo wall "
             "(median) | ratio (wall; CPU) | sim s (episode / bare) | load average |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        if "skipped" in row:
            return row["skipped"]
        if "vehicles_mean" not in row:
            continue
        before, after = row["load_average_1min"]
        lines.append(f"| {row['name'].split('.', 1)[1]} | {row['vehicles_mean']:.0f} / {row['vehicles_max']} "
                     "| "
                     f"{row['value']:.2f} s | {row['baseline']:.2f} s | {row['ratio']:.2f}; "
                     f"{row['cpu_ratio']:.2f} | {row['sim_seconds']:.0f} / {row['bare_sim_seconds']:.0f} | "
                     f"{before:.1f} → {after:.1f} |")
    slopes = [row for row in rows if row["name"] == "city_episode_seconds_per_vehicle"]
    if slopes:
        row = slopes[0]
        lines.append("\nper vehicle on the net: episode "
                     f"{1000 * row['episode_wall']['per_vehicle']:.2f} ms wall, "
                     f"{1000 * row['episode_cpu']['per_vehicle']:.2f} ms CPU; bare libsumo "
                     f"{1000 * row['bare_wall']['per_vehicle']:.2f} ms wall, "
                     f"{1000 * row['bare_cpu']['per_vehicle']:.2f} ms CPU (ratio {row['ratio']:.2f}; "
                     f"CPU {row['cpu_ratio']:.2f})")
    return "\n".join(lines)


if __name__ == "__main__":
    import json
    import sys

    _rows = run(int(sys.argv[1]) if len(sys.argv) > 1 else PAIRS)
    for _row in _rows:
        print(json.dumps(_row))
    print(markdown(_rows))
