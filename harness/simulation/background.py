"""Optional background traffic: seeded vehicles driving random routes on the town's roads.

`BackgroundTraffic(count, rng)` inserts `count` vehicles at the start of an episode, each on a
random road at a random position with a random destination (routes from SUMO's router), and
replaces every one that arrives, so the density stays `count`. Every draw comes from the
generator passed in (the episode's scene generator), so the same seed gives the same traffic.
Off by default (study key `background_vehicles`, docs/scenes.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from trustroute.harness.simulation.sumo_start import Sumo

TYPE_ID = "trustroute_background"
PREFIX = "bg"


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
