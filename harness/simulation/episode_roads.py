"""The road network an episode drives, chosen once: a net built from the town file, or an imported
town's own net (real_roads.py). Both answer the episode's questions behind one interface
(`EpisodeRoads`): which net SUMO loads and how it is checked, how long a road is, which edges a
road runs along and where each starts, where a road's incident is placed, how the ego's route is
started and extended one road ahead, and whether the background traffic is the episode's own
vehicles (a built net) or comes from route files (an imported net).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from trustroute.app.nets import net_for
from trustroute.harness.simulation.episode_net import check_net_matches, check_readable, net_key
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.incidents.base import Scene, lane_length
from trustroute.harness.simulation.manual_driving import one_edge
from trustroute.harness.simulation.real_roads import RealRoads, real_scene
from trustroute.harness.simulation.sumo_start import Sumo, SumoConfig
from trustroute.networks.real_net import is_imported, road_edges
from trustroute.networks.road import Road
from trustroute.networks.town import Town

UNSEEN_ROAD = 15.0   # metres: an imported road this short is crossed within a step (0.5 s at 30 m/s)


class EpisodeRoads(Protocol):
    """The town's roads as the SUMO net an episode drives."""

    net: Path
    imported: bool   # the town's own net: background traffic from route files, not the episode's

    def check(self, sumo: Sumo, setup: EpisodeSetup) -> None:
        """Once SUMO runs on the net: it holds the town's roads (InputError otherwise)."""
        ...

    def length(self, sumo: Sumo, road: str) -> float: ...

    def offsets(self, road: str) -> dict[str, float]:
        """Edge id -> where it starts along the road (the edges the ego is on while on `road`)."""
        ...

    def chain(self, road: str) -> tuple[str, ...]:
        """The SUMO edges `road` runs along, in driving order (its end is the last one's end)."""
        ...

    def place(self, kind: str, **scene: Any) -> Scene | None:
        """The scene of an incident of `kind` placed on the net, from the fields of a `Scene` given
        for the whole model road (all but its placement on the net: `reverse_road`,
        `observed_length` and the lanes and junctions); None: the incident cannot happen on this
        net. (Given as fields, so that a built net makes its Scene once: a copy with changed
        fields, dataclasses.replace, costs more than making one.)"""
        ...

    def start(self, road: str, depart: float) -> tuple[list[str], float]:
        """The ego's first route on the start road, `depart` metres in: (edges, depart position)."""
        ...

    def extend_route(self, sumo: Sumo, vehicle_id: str, road: str, nxt: str) -> list[str]:
        """The ego's route extended from `road` one road ahead, to `nxt`; returns the edges of a
        detour driven between them ([] without one)."""
        ...

    def crossed_within_a_step(self, sumo: Sumo, road: str) -> bool:
        """`road` is so short the ego may cross it within one step, never seen on it."""
        ...


class BuiltRoads:
    """A net built from the town file (networks/sumo_net.py): one edge per road, named by it."""

    imported = False

    def __init__(self, net: Path, key: tuple[str, float], town: Town, commit_distance: float) -> None:
        self.net = net
        self.key = key
        self.town = town
        self.commit_distance = commit_distance

    def check(self, sumo: Sumo, setup: EpisodeSetup) -> None:
        check_net_matches(sumo, setup, self.net, self.key)

    def length(self, sumo: Sumo, road: str) -> float:
        return lane_length(sumo, f"{road}_1")

    def offsets(self, road: str) -> dict[str, float]:
        return {road: 0.0}

    def chain(self, road: str) -> tuple[str, ...]:
        return one_edge(road)

    def place(self, kind: str, **scene: Any) -> Scene:
        other_way = Road.parse(scene["road"]).reverse.id
        reverse = other_way if other_way in self.town.incidents else None
        observed = scene["road_length"] - self.commit_distance
        return Scene(**scene, reverse_road=reverse, observed_length=observed)

    def start(self, road: str, depart: float) -> tuple[list[str], float]:
        return [road], depart

    def extend_route(self, sumo: Sumo, vehicle_id: str, road: str, nxt: str) -> list[str]:
        sumo.vehicle.setRoute(vehicle_id, [road, nxt])
        return []

    def crossed_within_a_step(self, sumo: Sumo, road: str) -> bool:
        return False


class ImportedRoads:
    """An imported town's own net: each road a chain of its edges (real_roads.py)."""

    imported = True

    def __init__(self, net: Path, real: RealRoads) -> None:
        self.net = net
        self.real = real

    def check(self, sumo: Sumo, setup: EpisodeSetup) -> None:
        """Checked against the hash the town recorded when the net was chosen (`episode_roads`)."""

    def length(self, sumo: Sumo, road: str) -> float:
        return self.real.length(road)

    def offsets(self, road: str) -> dict[str, float]:
        return self.real.offsets(road)

    def chain(self, road: str) -> tuple[str, ...]:
        return self.real.chain(road)

    def place(self, kind: str, **scene: Any) -> Scene | None:
        return real_scene(self.real, scene["road"], kind, Scene(**scene, reverse_road=None))

    def start(self, road: str, depart: float) -> tuple[list[str], float]:
        return self.real.start(road, depart)

    def extend_route(self, sumo: Sumo, vehicle_id: str, road: str, nxt: str) -> list[str]:
        return self.real.extend_route(sumo, vehicle_id, road, nxt)

    def crossed_within_a_step(self, sumo: Sumo, road: str) -> bool:
        return self.real.length(road) < UNSEEN_ROAD


def episode_roads(town: Town, net_path: Path | None, commit_distance: float) -> EpisodeRoads:
    """The roads an episode on `town` drives: an imported town's own net (checked against the hash
    the town recorded), or `net_path` (default: the town's built net, cached)."""
    if is_imported(town):
        own = net_for(town)   # checked against the town's hash even when a net is given
        net = own if net_path is None else Path(net_path)
        roads: EpisodeRoads = ImportedRoads(net, RealRoads(road_edges(town, net), commit_distance))
        net_key(net)   # a missing file is the one-line error
        return roads
    if net_path is None:
        net = net_for(town)
    else:   # a Path given is used as it is: making it again parses each of its parts, every episode
        net = net_path if isinstance(net_path, Path) else Path(net_path)
    key = net_key(net)
    if net_path is not None:
        check_readable(net, key)
    return BuiltRoads(net, key, town, commit_distance)


def background_vehicles(roads: EpisodeRoads, config: SumoConfig) -> int:
    """The background vehicles the episode inserts itself (an imported net's come from route files)."""
    return 0 if roads.imported else config.background_vehicles
