"""Failure and takeover rates of the incident scenes on an imported town (docs/scenes.md, "The
scenes on real nets"), measured as on Town01 (benchmarks/bench_episode.py) but over several routes.

    .venv/bin/python docs/scene_rates.py TOWN EPISODES --routes N [--json OUT]

Run from the repository root. Routes: the fewest roads through every incident kind
(`route_through_every_kind`) from N start roads spread evenly over the town's sorted roads; a start
whose first episode cannot run (the ego cannot be inserted, a scene vehicle refused by the net) is
left out and named. Episode k drives route k mod N with seed 2000 + k (scene and driver draws), the
default driver model, trust-free, no fallback, no background traffic. Per kind, over every road of
that kind driven after the start road (the roads table): failures among the roads driven on
autopilot with a 95 % Wilson interval, the takeover rate, how many scenes were placed in SUMO (the
incidents table's rows with SUMO objects), the failing measures of every failed road and the
roads they failed on, and the mean time lost on placed scenes.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import binomtest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_episode import route_through_every_kind  # noqa: E402
from trustroute.harness.simulation import episode as episode_module  # noqa: E402
from trustroute.harness.simulation.episode import EpisodeOptions, run_episode  # noqa: E402
from trustroute.harness.simulation.episode_tracker import EpisodeSetup  # noqa: E402
from trustroute.harness.simulation.sumo_start import SumoConfig  # noqa: E402
from trustroute.networks.town import NO_INCIDENT, load_town  # noqa: E402
from trustroute.participants.driver_model import load_driver_model  # noqa: E402
from trustroute.participants.synthetic_driver import SyntheticDriver  # noqa: E402
from trustroute.policies.logic.spec import load_spec  # noqa: E402
from trustroute.policies.routing.fixed_route import FixedRoute  # noqa: E402


def record_failed_measures(failed: collections.Counter) -> None:
    """Count (kind, road, failing measures) of every road that fails, placed scene or not (the
    incidents table has a row only where the scene was placed or the driver took over)."""
    close_road = episode_module._Episode.close_road

    def counting(self, run, now) -> None:
        close_road(self, run, now)
        measures = run.monitor.failed_measures(self.limits(run))
        if measures and not run.took_over:
            failed[(run.kind, run.road, ",".join(measures))] += 1

    episode_module._Episode.close_road = counting


def routes_and_setups(town, model, folder: Path, n_routes: int):
    starts = town.states[::max(1, len(town.states) // n_routes)][:n_routes]
    kept, refused = [], {}
    for i, start in enumerate(starts):
        route = route_through_every_kind(town, start)
        spec = folder / f"scene_rates_{i}.toml"
        spec.write_text(f'name = "rates"\nstart = "{start}"\nformula = "F v1"\n\n'
                        f'[states]\nv1 = ["{route[-1]}"]\n')
        setup = EpisodeSetup(town=town, driver_model=model, spec=load_spec(str(spec), town),
                             fallback_after=None)
        try:
            driver = SyntheticDriver(model, np.random.default_rng(1))
            run_episode(setup, FixedRoute(route), driver, "probe", 1)
        except Exception as exc:  # a start the net cannot run: named in the output
            refused[start] = f"{type(exc).__name__}: {exc}"
            continue
        kept.append((route, setup))
    return kept, refused


def kind_rates(kind: str, roads: pd.DataFrame, incidents: pd.DataFrame, failed: collections.Counter) -> dict:
    auto = roads[~roads["takeover"].astype(bool)]
    failures = int((auto["performance"] == "fail").sum())
    placed = incidents[(incidents["incident"] == kind) & incidents["sumo_ids"].notna()]
    interval = binomtest(failures, len(auto)).proportion_ci(method="wilson") if len(auto) else None
    return {
        "roads": len(roads), "autopilot": len(auto), "failures": failures,
        "ci95": [interval.low, interval.high] if interval else None,
        "takeover_rate": float(roads["takeover"].mean()),
        "placed": len(placed), "distinct_roads": int(roads["directed_road"].nunique()),
        "distinct_roads_placed": int(placed["directed_road"].nunique()),
        "collisions": int(incidents[incidents["incident"] == kind]["collided"].sum()),
        "time_lost_placed": float(placed["time_lost"].mean()) if len(placed) else None,
        "failed": {f"{road}: {measures}": count for (k, road, measures), count in sorted(failed.items())
                   if k == kind},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("town")
    parser.add_argument("episodes", type=int)
    parser.add_argument("--routes", type=int, default=10)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    town = load_town(args.town)
    model = load_driver_model(None)
    failed: collections.Counter = collections.Counter()
    with tempfile.TemporaryDirectory(prefix="scene-rates-") as folder:
        kept, refused = routes_and_setups(town, model, Path(folder), args.routes)
    record_failed_measures(failed)
    roads, incidents, started = [], [], time.perf_counter()
    for k in range(args.episodes):
        route, setup = kept[k % len(kept)]
        driver = SyntheticDriver(model, np.random.default_rng(2000 + k))
        record = run_episode(setup, FixedRoute(route), driver, f"rates{k}", 2000 + k,
                             EpisodeOptions(config=SumoConfig()))
        roads.append(record.roads)
        incidents.append(record.incidents)
    all_roads = pd.concat(roads, ignore_index=True)
    all_roads = all_roads[(all_roads["index"] > 0) & (all_roads["incident"] != NO_INCIDENT)]
    all_incidents = pd.concat(incidents, ignore_index=True)
    result = {
        "town": args.town, "episodes": args.episodes, "routes": [" ".join(r) for r, _ in kept],
        "refused_starts": refused, "wall_seconds": time.perf_counter() - started,
        "load_average_1min": os.getloadavg()[0],
        "kinds": {kind: kind_rates(kind, group, all_incidents, failed)
                  for kind, group in all_roads.groupby("incident")},
    }
    text = json.dumps(result, indent=1)
    if args.json is not None:
        args.json.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
