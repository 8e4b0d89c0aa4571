"""One SUMO episode (phi1, trust-free policy, driver, incidents) vs a bare libsumo loop on the same route.

The bare loop starts SUMO with the same command line, inserts the ego with the whole baseline route,
steps until it arrives and closes SUMO: no policy, driver, incidents or logging. The episode is run
as a study's worker runs its episodes, one after another in one process: it returns the simulation
the process keeps open to its empty state (sumo_start.sumo_session) and includes handing its logs
back as Arrow tables (EpisodeRecord.tables), the form a study writes. libsumo runs one simulation
per process, so the episodes run in one process and the bare loops in another, called in
interleaved pairs, each timed in its own process (benchmarks/timing.py TimingProcess). Both are
measured in the same run; the ratio is episode / bare. Also: memory growth over 200 episodes in
one process, and the measured failure rate, takeover rate and time lost per incident kind over 200
episodes on a route through every kind (route_through_every_kind).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.timing import TimingProcess, paired_timings
from trustroute.harness.simulation.episode import (
    COMMIT_DISTANCE,
    START_BEFORE_COMMIT,
    EpisodeOptions,
    run_episode,
)
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.incidents import truck
from trustroute.harness.simulation.sumo_start import SumoConfig, fresh_session, sumo_session
from trustroute.networks.road import Road
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.fixed_route import FixedRoute
from trustroute.policies.routing.free import baseline_route, trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy

SEED = 3
PAIRS = 41   # (episode, bare) pairs of the ratio
KINDS = ("pedestrian", "obstacle", "truck")


def full_scene(town, road: str) -> bool:
    """Every variant of the road's scene can happen there: a truck road's opposite lane has room
    for the truck to overtake a parked car (truck.PARKED_MIN_LANE; the town's length, within the
    net's 5 % of the SUMO lane's), the only way an oncoming truck enters the ego's lane."""
    if town.incident(road) != "truck":
        return True
    u, v = Road.parse(road)
    return town.length(f"{v}-{u}") >= truck.PARKED_MIN_LANE


def route_through_every_kind(town, start: str) -> tuple[str, ...]:
    """The fewest roads from `start` (breadth first over directed roads and kinds met, ties by the
    town's order of moves) that meet every incident kind on a road where its whole scene can
    happen (`full_scene`; kinds on other roads are measured too): the route the rates are
    measured on, whatever the town."""
    from collections import deque

    queue = deque([((start,), frozenset())])
    seen = {(start, frozenset())}
    while queue:
        route, met = queue.popleft()
        if met >= set(KINDS):
            return route
        for nxt in town.successors(route[-1]):
            kinds = met | ({town.incident(nxt)} & set(KINDS) if full_scene(town, nxt) else set())
            if (nxt, kinds) not in seen:
                seen.add((nxt, kinds))
                queue.append((route + (nxt,), kinds))
    raise ValueError("the town has no route through every incident kind")


def bare_loop(net, route: list[str], config: SumoConfig, keep_open: bool = False) -> float:
    """Start SUMO with the episode's command line, drive `route` with nothing else, close SUMO;
    returns the sim seconds. keep_open: in the simulation kept open between runs, as the episodes
    do (sumo_session), so only SUMO's start-up differs from the episode."""
    with (sumo_session if keep_open else fresh_session)(net, SEED, config) as sumo:
        sumo.route.add("r", route)
        # Same start point as the episode's ego; it drives the route to its very end.
        depart = max(0.0, sumo.lane.getLength(f"{route[0]}_1") - COMMIT_DISTANCE - START_BEFORE_COMMIT)
        sumo.vehicle.add("ego", "r", depart="now", departPos=f"{depart:.2f}", departSpeed="max")
        sumo.vehicle.subscribe("ego", [sumo.VAR_ROAD_ID, sumo.VAR_POSITION, sumo.VAR_SPEED])
        seen = False
        while True:
            sumo.simulationStep()
            if sumo.vehicle.getSubscriptionResults("ego"):
                seen = True
            elif seen:
                return sumo.simulation.getTime()


def _rss_mb() -> float:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


@dataclass(frozen=True)
class MeasuredEpisode:
    """The measured episode (φ1 on the default town, trust-free policy, default driver) and the
    bare libsumo loop of the same route: what `run` and bench_episode_profile.py both time."""

    setup: EpisodeSetup
    policy: RoutingPolicy
    net: Path
    config: SumoConfig
    route: list[str]

    def episode(self, seed: int = SEED):
        driver = SyntheticDriver(self.setup.driver_model, np.random.default_rng(seed))
        record = run_episode(self.setup, self.policy, driver, f"bench{seed}", seed,
                             EpisodeOptions(net_path=self.net, config=self.config))
        record.tables()   # the logs in the form a study writes them (Arrow), part of the cost
        return record

    def bare(self) -> float:
        return bare_loop(self.net, self.route, self.config)

    def bare_kept_open(self) -> float:
        return bare_loop(self.net, self.route, self.config, keep_open=True)


def measured_episode() -> MeasuredEpisode:
    town = load_town()
    spec = load_spec("phi1", town)
    return MeasuredEpisode(setup=EpisodeSetup(town=town, driver_model=load_driver_model(), spec=spec),
                           policy=trust_free_policy(town, spec), net=build_net(town).path,
                           config=SumoConfig(), route=baseline_route(town, spec))


def run() -> list[dict]:
    measured = measured_episode()
    setup, net, config, episode = measured.setup, measured.net, measured.config, measured.episode
    # Interleaved pairs, median of the per-pair ratios, in wall and in CPU time of each side's
    # process (libsumo runs in it; CPU time is less disturbed by the other processes of a shared
    # machine). The first call of each warms its path (the episode's starts SUMO).
    with TimingProcess(episode) as timed_episode, TimingProcess(measured.bare) as timed_bare:
        first_episode = timed_episode()
        timed_bare()
        paired = paired_timings(timed_episode, timed_bare, pairs=PAIRS)
    # The same episodes against bare loops that also keep their simulation open: what the harness
    # adds to SUMO's stepping of the same route, start-up left out of both.
    with TimingProcess(episode) as timed_episode, TimingProcess(measured.bare_kept_open) as timed_open:
        timed_episode()
        timed_open()
        kept_open = paired_timings(timed_episode, timed_open, pairs=PAIRS)
    record = episode()
    bare_sim = measured.bare()

    for seed in range(20):
        episode(100 + seed)
    before = _rss_mb()
    started = time.perf_counter()
    for seed in range(200):
        episode(1000 + seed)
    many_seconds = time.perf_counter() - started
    growth = _rss_mb() - before
    rates = incident_rates(setup, net, config)
    return [
        {"name": "episode_phi1_wall", "value": paired["target_wall_median"], "unit": "s",
         "baseline": paired["baseline_wall_median"], "ratio": paired["wall_ratio_median"],
         "target_ratio": 1.2, "cpu_ratio": paired["cpu_ratio_median"],
         "ratio_what": f"median of {PAIRS} interleaved (episode, bare) pairs, wall and CPU time; "
                       "the episodes in one process, one after another, as a study worker runs them",
         "first_episode_wall": first_episode[0], "first_episode_cpu": first_episode[1],
         **{key: value for key, value in paired.items() if not key.endswith("ratio_median")},
         "sim_seconds": record.summary["sim_seconds"],
         "bare_sim_seconds": bare_sim, "step_length": config.step_length,
         # the incidents make the episode longer in sim time (waiting, following a truck)
         "ratio_per_sim_second": paired["wall_ratio_median"] * bare_sim / record.summary["sim_seconds"]},
        {"name": "episode_phi1_bare_libsumo", "value": paired["baseline_wall_median"], "unit": "s"},
        {"name": "episode_phi1_vs_bare_kept_open", "value": kept_open["target_wall_median"], "unit": "s",
         "baseline": kept_open["baseline_wall_median"], "ratio": kept_open["wall_ratio_median"],
         "cpu_ratio": kept_open["cpu_ratio_median"],
         "ratio_what": f"median of {PAIRS} interleaved pairs against a bare loop that keeps its simulation "
                       "open too (no target: SUMO's start-up left out of both)",
         **{key: value for key, value in kept_open.items() if not key.endswith("ratio_median")}},
        {"name": "episodes_200_wall", "value": many_seconds, "unit": "s"},
        {"name": "episodes_200_rss_growth", "value": growth, "unit": "MB"},
        *rates,
        study_against_bare(21),
        study_against_bare(105),
    ]


def _wilson(failures: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion (small counts: say how approximate)."""
    if n == 0:
        return float("nan"), float("nan")
    p = failures / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def incident_rates(setup: EpisodeSetup, net, config: SumoConfig, episodes: int = 200) -> list[dict]:
    """Failure rate (on autopilot), takeover rate, collisions and time lost per incident kind over
    `episodes` seeded episodes with the default driver on a route through every kind (the phi1
    route has no obstacle)."""
    route = route_through_every_kind(setup.town, setup.spec.start)
    scenes = EpisodeSetup(town=setup.town, driver_model=setup.driver_model, spec=setup.spec,
                          fallback_after=None)
    incidents = []
    for seed in range(episodes):
        driver = SyntheticDriver(setup.driver_model, np.random.default_rng(2000 + seed))
        incidents.append(run_episode(scenes, FixedRoute(route), driver, f"rates{seed}", 2000 + seed,
                                     EpisodeOptions(net_path=net, config=config)).incidents)
    rows = pd.concat(incidents, ignore_index=True)
    rates = []
    for kind, group in rows.groupby("incident"):
        auto = group[~group["takeover"]]   # performance is measured on autopilot only
        failures = int((auto["performance"] == "fail").sum())
        low, high = _wilson(failures, len(auto))
        measures = auto["failed_measures"].dropna().str.split(",").explode().value_counts()
        rates.append({"name": f"episode_failure_rate.{kind}",
                      "value": failures / len(auto) if len(auto) else float("nan"), "unit": "fraction",
                      "failures": failures, "roads_on_autopilot": int(len(auto)), "ci95": [low, high],
                      "failed_measures": {str(k): int(v) for k, v in measures.items()},
                      "collisions": int(group["collided"].sum()),
                      "takeover_rate": float(group["takeover"].mean()),
                      "mean_time_lost": float(group["time_lost"].mean()),
                      "mean_time_lost_autopilot": float(auto["time_lost"].mean()),
                      "episodes": episodes, "route": " ".join(route)})
    return rates


def _bare_route(args) -> float:
    """One bare loop (process-pool worker): (net path, route) -> sim seconds."""
    net, route = args
    return bare_loop(net, list(route), SumoConfig())


def _bare_routes(net, routes: list[tuple[str, ...]], workers: int) -> float:
    """Wall seconds of bare loops driving `routes` on `workers` processes."""
    from concurrent.futures import ProcessPoolExecutor

    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        list(pool.map(_bare_route, [(net, route) for route in routes]))
    return time.perf_counter() - started


def study_against_bare(participants: int = 21, workers: int = 2,
                       conditions: tuple[str, ...] = ("free",)) -> dict:
    """A SUMO study (`conditions`, phi1 and phi2, `workers` processes, parts written and
    consolidated) against bare libsumo loops driving the very routes its episodes drove, on the
    same number of processes; the ratio is study wall / bare wall (throughput ratio), with the
    load average before the study, after it and after the bare loops beside it."""
    import tempfile
    from pathlib import Path

    from trustroute.core.dataset import read_roads
    from trustroute.harness.study.config import study_config_from_dict
    from trustroute.harness.study.runner import run_and_consolidate, validate_study

    net = build_net(load_town()).path
    config = study_config_from_dict({"study": {
        "name": "bench-study-vs-bare", "participants": participants, "seed": 1, "engine": "sumo",
        "specs": ["phi1", "phi2"], "conditions": list(conditions)}}, "bench_episode", Path.cwd())
    # the study's context, built before the clock starts (a missing "aware" policy synthesized into
    # the cache), and handed to the run
    context = validate_study(config)
    load = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory(prefix="trustroute-bench-") as folder:
        started = time.perf_counter()
        run, _ = run_and_consolidate(context, Path(folder) / "study", workers, None, progress=False,
                                     echo=lambda *_: None)
        study_seconds = time.perf_counter() - started
        roads = read_roads(Path(folder) / "study")
    load.append(os.getloadavg()[0])
    routes = [tuple(group.sort_values("index")["directed_road"]) for _, group in roads.groupby("episode_id")]
    bare_seconds = _bare_routes(net, routes, workers)
    load.append(os.getloadavg()[0])
    return {"name": f"study_sumo_vs_bare_libsumo.{len(routes)}_episodes", "value": study_seconds, "unit": "s",
            "baseline": bare_seconds, "ratio": study_seconds / bare_seconds, "episodes": len(routes),
            "load_average_1min": load,
            "workers": workers, "failed": len(run.failed), "target_ratio": 1.3,
            "what": f"conditions {', '.join(conditions)}, policies synthesized before the clock; bare = "
                    "the same routes, same process count"}


def _rates_table(rates: list[dict]) -> str:
    lines = ["| kind | failure rate (autopilot roads) | 95 % interval | failing measures | collisions "
             "| takeover rate | mean time lost |", "|---|---|---|---|---|---|---|"]
    for row in rates:
        low, high = row["ci95"]
        lines.append(f"| {row['name'].rsplit('.', 1)[1]} | {100 * row['value']:.1f} % ({row['failures']} of "
                     f"{row['roads_on_autopilot']}) | {100 * low:.1f}–{100 * high:.1f} % | "
                     f"{', '.join(f'{k} {v}' for k, v in row['failed_measures'].items()) or '—'} | "
                     f"{row['collisions']} | {100 * row['takeover_rate']:.1f} % | "
                     f"{row['mean_time_lost']:.1f} s |")
    return "\n".join(lines)


if __name__ == "__main__":
    # `python -m benchmarks.bench_episode [EPISODES [TOWN_JSON]]`: the per-kind rates alone, as a
    # table, on the default town or the given one.
    import sys

    _town = load_town(sys.argv[2] if len(sys.argv) > 2 else None)
    _spec = load_spec("phi1", _town)
    _setup = EpisodeSetup(town=_town, driver_model=load_driver_model(), spec=_spec)
    print("route:", " ".join(route_through_every_kind(_town, _spec.start)))
    print(_rates_table(incident_rates(_setup, build_net(_town).path, SumoConfig(),
                                      int(sys.argv[1]) if len(sys.argv) > 1 else 200)))
