"""Optional background traffic: seeded vehicles driving random routes on the town's roads.

On a town built by `trustroute net build`, `BackgroundTraffic(count, rng)` inserts `count` vehicles
at the start of an episode, each on a random road at a random position with a random destination
(routes from SUMO's router), and replaces every one that arrives, so the density stays `count`.
Every draw comes from the generator passed in (the episode's scene generator), so the same seed
gives the same traffic.
Off by default (study key `background_vehicles`, docs/scenes.md).

On an imported town's own net the traffic comes from route files SUMO loads with the net: the
scenario's own (`trustroute run --routes FILE`, study key `routes`), or trips written by SUMO's
`randomTrips.py` (`random_trips`): `count` passenger cars departing per minute, from and to
random passenger edges, with a seed derived from the episode's seed (`trips_seed`), so the same
episode seed gives the same traffic. SUMO routes each trip when it departs. A scenario's demand
usually starts at its own time of day: `shifted_routes` moves every departure by one offset so the
first one leaves when the episode starts (at 0 s). The episode never teleports a vehicle (a stuck
ego must show up as stuck), and a city's traffic without teleports can lock itself at a junction
for good; `JamRelief` takes out a background vehicle that has stood for `STUCK_SECONDS`, as
SUMO's own --time-to-teleport would, and leaves the ego and the incidents' vehicles alone.

An episode still running at its sim-time cap (SumoConfig.max_sim_seconds) ends with
`SimTimeCapReached`. When the ego stands in background traffic, the traffic has locked up (a town
and seed can jam with fewer vehicles than the most a door takes, defaults.MAX_BACKGROUND_VEHICLES):
that is `TrafficJam`, bad input told in one line with its fix. Otherwise nothing should hold the
ego up that long: a bug, raised with its traceback.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from trustroute.core.errors import InputError
from trustroute.harness.simulation.sumo_start import Sumo, SumoConfig
from trustroute.networks.cities import read_route_file

TYPE_ID = "trustroute_background"
PREFIX = "bg"
TRIPS_STREAM = 0xB6C7        # the trips' seed: SeedSequence([episode seed, TRIPS_STREAM])
TRIPS_PER = 60.0             # seconds: `count` trips depart in every such interval
TRIPS_END = 7200.0           # seconds of departures written (the longest an episode may run)


TIMED = (("vehicle", "depart"), ("trip", "depart"), ("person", "depart"), ("container", "depart"),
         ("flow", "begin"), ("flow", "end"), ("personFlow", "begin"), ("personFlow", "end"))


def _seconds(value: str | None) -> float | None:
    try:
        return float(value) if value is not None else None
    except ValueError:   # "triggered", "now", a clock time: left as written
        return None


def shifted_routes(files: tuple[str, ...], folder: Path) -> tuple[str, ...]:
    """The route files with every numeric departure moved by one offset, so the earliest is 0 s
    (files without a departure, such as vehicle types, are passed through unchanged)."""
    trees = [read_route_file(name) for name in files]
    times = [t for tree in trees for tag, key in TIMED[:5] for element in tree.iter(tag)
             if (t := _seconds(element.get(key))) is not None]
    offset = min(times, default=0.0)
    out = []
    for index, (name, tree) in enumerate(zip(files, trees, strict=True)):
        if offset == 0.0 or not any(True for tag, _ in TIMED for _ in tree.iter(tag)):
            out.append(name)
            continue
        for tag, key in TIMED:
            for element in tree.iter(tag):
                value = _seconds(element.get(key))
                if value is not None:
                    element.set(key, f"{value - offset:.3f}")
        target = Path(folder) / f"routes{index}.rou.xml"
        tree.write(target, encoding="UTF-8", xml_declaration=True)
        out.append(str(target))
    return tuple(out)


STUCK_SECONDS = 120.0        # a background vehicle standing this long is taken out
CHECK_EVERY = 10.0           # seconds of sim time between two looks for stuck vehicles


@dataclass
class JamRelief:
    """The per-step call that takes stuck background vehicles out (route-file traffic only)."""

    keep: str                          # the ego's id
    keep_prefix: str = "inc"           # the incidents' vehicles
    next_check: float = CHECK_EVERY
    removed: int = 0

    def step(self, sumo: Sumo) -> None:
        now = sumo.simulation.getTime()
        if now < self.next_check:
            return
        self.next_check = now + CHECK_EVERY
        for vehicle_id in sumo.vehicle.getIDList():
            if vehicle_id == self.keep or vehicle_id.startswith(self.keep_prefix):
                continue
            if sumo.vehicle.getWaitingTime(vehicle_id) >= STUCK_SECONDS:
                sumo.vehicle.remove(vehicle_id)
                self.removed += 1


def trips_seed(seed: int) -> int:
    """randomTrips.py's seed for an episode seed (a stream of its own: it never shifts the scenes')."""
    return int(np.random.SeedSequence([int(seed), TRIPS_STREAM]).generate_state(1)[0])


def random_trips_script() -> Path:
    """SUMO's randomTrips.py, from the eclipse-sumo wheel's tools."""
    import sumo

    return Path(sumo.SUMO_HOME) / "tools" / "randomTrips.py"


def random_trips(net_file: Path, seed: int, count: int, folder: Path, end: float = TRIPS_END) -> Path:
    """`folder/background.trips.xml`: `count` passenger trips per TRIPS_PER seconds on `net_file`
    from randomTrips.py, seeded by `trips_seed(seed)`. Not checked for connectivity (randomTrips'
    --validate routes every trip with duarouter, about half a second more per episode): SUMO
    leaves out a trip it cannot route (sumo_start, --ignore-route-errors)."""
    out = Path(folder) / "background.trips.xml"
    command = [sys.executable, str(random_trips_script()), "-n", str(Path(net_file).resolve()),
               "-o", str(out.resolve()),
               "--seed", str(trips_seed(seed)), "-b", "0", "-e", f"{end:g}", "-p", f"{TRIPS_PER / count:g}",
               "--vehicle-class", "passenger", "--edge-permission", "passenger", "--prefix", PREFIX,
               "--trip-attributes", 'departLane="best" departSpeed="max"', "--no-validate"]
    # Run inside `folder`: randomTrips.py writes helper files into its working directory.
    result = subprocess.run(command, capture_output=True, text=True, check=False, cwd=folder,
                            env={**os.environ, "SUMO_HOME": str(random_trips_script().parents[1])})
    if result.returncode != 0 or not out.is_file():
        message = (result.stderr or result.stdout).strip().splitlines()
        raise InputError(str(net_file), "", "randomTrips.py could not write background trips"
                         + (f" ({message[-1]})" if message else ""),
                         "pass the scenario's own routes with --routes, or set background_vehicles = 0")
    return out


def define_type(sumo: Sumo) -> None:
    sumo.vehicletype.copy("DEFAULT_VEHTYPE", TYPE_ID)
    sumo.vehicletype.setColor(TYPE_ID, (150, 200, 150, 255))


@dataclass
class BackgroundTraffic:
    count: int
    rng: np.random.Generator
    roads: tuple[str, ...]
    lengths: dict[str, float] = field(default_factory=dict)
    inserted: int = 0
    live: set[str] = field(default_factory=set)

    def start(self, sumo: Sumo) -> None:
        if self.count <= 0:
            return
        define_type(sumo)
        for road in self.roads:
            self.lengths[road] = sumo.lane.getLength(f"{road}_1")
        for _ in range(self.count):
            self._add(sumo, anywhere=True)

    def _add(self, sumo: Sumo, anywhere: bool) -> None:
        for _ in range(20):   # a random pair can be unroutable only in odd towns: draw again
            start, end = self.rng.choice(len(self.roads), size=2, replace=False)
            fraction = float(self.rng.uniform(0.1, 0.9)) if anywhere else 0.0
            position = fraction * self.lengths[self.roads[start]]
            route = sumo.simulation.findRoute(self.roads[start], self.roads[end]).edges
            if route:
                break
        else:
            return
        vehicle_id = f"{PREFIX}{self.inserted}"
        self.inserted += 1
        sumo.route.add(f"{vehicle_id}_route", list(route))
        sumo.vehicle.add(vehicle_id, f"{vehicle_id}_route", typeID=TYPE_ID, depart="now", departLane="1",
                         departPos=f"{position:.2f}", departSpeed="desired")
        self.live.add(vehicle_id)

    def step(self, sumo: Sumo) -> None:
        """Replace arrived vehicles (called every step only when there is background traffic)."""
        if sumo.simulation.getArrivedNumber():
            for vehicle_id in sumo.simulation.getArrivedIDList():
                if vehicle_id in self.live:
                    self.live.discard(vehicle_id)
                    self._add(sumo, anywhere=False)


def background_routes(config, imported: bool, net_file: Path, seed: int, folder: Path) -> tuple[str, ...]:
    """The route files SUMO loads with the net: the given ones shifted to start with the episode, or
    on an imported town without them, `config.background_vehicles` trips per minute from
    randomTrips.py (SumoConfig `config`)."""
    if config.route_files:
        return shifted_routes(tuple(config.route_files), folder)
    if imported and config.background_vehicles > 0:
        return (str(random_trips(net_file, seed, config.background_vehicles, folder,
                                 end=config.max_sim_seconds)),)
    return ()


class SimTimeCapReached(RuntimeError):
    """The episode was still running at its sim-time cap (SumoConfig.max_sim_seconds)."""


class TrafficJam(InputError, SimTimeCapReached):
    """The sim-time cap reached with the ego standing in background traffic: the traffic locked up."""


def sim_time_cap_reached(episode_id: str, road: str, standing: float,
                         config: SumoConfig) -> SimTimeCapReached:
    """The error of an episode at its sim-time cap, the ego on `road` and standing for `standing`
    seconds: a TrafficJam when it stood for STUCK_SECONDS or more in background traffic."""
    cap = f"{config.max_sim_seconds:.0f} s"
    if standing >= STUCK_SECONDS and config.background_vehicles > 0:
        return TrafficJam(f"episode {episode_id}", road,
                          f"the ego stood still until the {cap} sim-time cap: the "
                          f"{config.background_vehicles} background vehicles jammed the town's roads",
                          "run it with fewer background vehicles (background_vehicles, `trustroute run "
                          "--background N`); how many a town carries depends on its roads and the seed")
    if standing >= STUCK_SECONDS and config.route_files:
        return TrafficJam(f"episode {episode_id}", road,
                          f"the ego stood still until the {cap} sim-time cap: the route files' "
                          "traffic jammed the town's roads",
                          "run it with a lighter demand (fewer or smaller route files: routes, "
                          "`trustroute run --routes FILE`)")
    return SimTimeCapReached(f"episode {episode_id} still running after {cap} of sim time on {road}")
