"""Finding a town's roads by what a person knows of a map: the roads into a junction, the roads
of a street, the roads near a point, and how many junctions apart two sets of roads are.

Spec files name waypoint sets by junction or street through these (policies/logic/spec.py,
docs/formats/spec.md); `trustroute town roads` prints them; `trustroute spec check` reports the
junction distances between consecutive waypoint sets.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass

from trustroute.networks.road import Road
from trustroute.networks.town import Town

STREET_SEPARATOR = "; "  # an imported road along several streets names them all, joined by this


def road_shape(town: Town, directed_road: str) -> tuple[tuple[float, float], ...]:
    """The road's course: its geometry's shape, or the straight line between its junctions."""
    geometry = town.geometry.get(directed_road)
    if geometry is not None:
        return geometry.shape
    u, v = Road.parse(directed_road)
    return (town.junctions[u], town.junctions[v])


def road_streets(town: Town, directed_road: str) -> tuple[str, ...]:
    """The street names a road runs along (none for a road without a geometry street)."""
    geometry = town.geometry.get(directed_road)
    if geometry is None or not geometry.street:
        return ()
    return tuple(name.strip() for name in geometry.street.split(STREET_SEPARATOR) if name.strip())


def roads_into(town: Town, junction: str) -> frozenset[str]:
    """Every directed road of the town that ends at `junction`."""
    return frozenset(road for road in town.states if Road.parse(road).to_junction == junction)


def unknown_road_fix(town: Town, road_id: str) -> str:
    """The fix for a directed road id "U-V" that `town` lacks: its other direction when that is a
    road of the town (a one-way street written the other way round), else the roads leaving U when
    U is a junction of the town, else a few of the town's roads."""
    road = Road.parse_or_none(road_id)
    if road is not None and road.reverse.id in town.states:
        return (f"the road between {road.from_junction} and {road.to_junction} is one-way, driven from "
                f"{road.to_junction} to {road.from_junction}: write '{road.reverse.id}' ('U-V' is "
                "driven from U to V)")
    leaving = [] if road is None else sorted(r for r in town.states
                                             if Road.parse(r).from_junction == road.from_junction)
    examples = ", ".join(leaving[:5] or sorted(town.states)[:3])
    where = f"from {road.from_junction}: " if leaving and road is not None else "e.g. "
    return f"use directed roads 'U-V' of the town, the keys of its \"incidents\" ({where}{examples})"


def roads_on_street(town: Town, street: str) -> frozenset[str]:
    """Every directed road one of whose street names is `street` (case and surrounding spaces
    ignored)."""
    wanted = street.strip().casefold()
    return frozenset(road for road in town.states
                     if any(name.casefold() == wanted for name in road_streets(town, road)))


def street_names(town: Town) -> tuple[str, ...]:
    """Every street name of the town, sorted."""
    return tuple(sorted({name for road in town.states for name in road_streets(town, road)}))


def point_to_segment(point: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
    (px, py), (ax, ay), (bx, by) = point, a, b
    dx, dy = bx - ax, by - ay
    span = dx * dx + dy * dy
    t = 0.0 if span == 0 else max(0.0, min(1.0, ((px - ax) * dx + (py - ay) * dy) / span))
    return math.hypot(px - (ax + t * dx), py - (ay + t * dy))


def distance_to_road(town: Town, directed_road: str, point: tuple[float, float]) -> float:
    """Metres from `point` to the nearest point of the road's course."""
    shape = road_shape(town, directed_road)
    return min(point_to_segment(point, a, b) for a, b in zip(shape, shape[1:], strict=False))


@dataclass(frozen=True)
class RoadRow:
    """One road as `trustroute town roads` prints it."""

    road: str
    length: float
    street: str
    incident: str
    distance: float | None = None  # metres from the asked point, when one was asked

    def to_dict(self) -> dict:
        out = {"road": self.road, "length": round(self.length, 3), "street": self.street,
               "incident": self.incident}
        if self.distance is not None:
            out["distance"] = round(self.distance, 3)
        return out


def road_rows(town: Town, near: tuple[float, float] | None = None, street: str | None = None,
              limit: int | None = None) -> list[RoadRow]:
    """The town's roads (those on `street` when given), nearest to `near` first when given (else in
    the town's order), at most `limit`."""
    roads: Iterable[str] = town.states if street is None else sorted(roads_on_street(town, street))
    rows = [RoadRow(road=road, length=town.length(road), incident=town.incident(road),
                    street=STREET_SEPARATOR.join(road_streets(town, road)),
                    distance=None if near is None else distance_to_road(town, road, near)) for road in roads]
    if near is not None:
        rows.sort(key=lambda row: (row.distance, row.road))
    return rows if limit is None else rows[:limit]


def junctions_apart(town: Town, sources: Iterable[str], targets: Iterable[str]) -> int | None:
    """The fewest junctions a car passes driving from any road of `sources` onto any road of
    `targets` (0 when they share a road), by the town's moves; None when no target is reachable."""
    target_set = set(targets)
    hops = {road: 0 for road in sources}
    queue = deque(hops)
    while queue:
        road = queue.popleft()
        if road in target_set:
            return hops[road]
        for nxt in town.successors(road):
            if nxt not in hops:
                hops[nxt] = hops[road] + 1
                queue.append(nxt)
    return None


@dataclass(frozen=True)
class WaypointLeg:
    """From one waypoint set (or the start road) to the next: the fewest junctions between them."""

    source: str  # "start" or an atom name
    target: str
    junctions: int | None  # None: the target cannot be reached from the source

    def to_dict(self) -> dict:
        return {"from": self.source, "to": self.target, "junctions": self.junctions}


def waypoint_legs(town: Town, start: str,
                  waypoints: Iterable[tuple[str, frozenset[str]]]) -> list[WaypointLeg]:
    """The junction distances of consecutive waypoint sets, from the start road: each leg from the
    whole previous set (the car may be on any of its roads) to the nearest road of the next."""
    legs = []
    previous_name, previous = "start", frozenset({start})
    for name, roads in waypoints:
        legs.append(WaypointLeg(previous_name, name, junctions_apart(town, previous, roads)))
        previous_name, previous = name, roads
    return legs



def choice_junctions(town: Town) -> set[str]:
    """The junctions where a car arriving on some road has two or more moves other than the U-turn
    (the road back to the junction it came from): the decision junctions of the model."""
    found = set()
    for directed_road in town.states:
        came_from, at = Road.parse(directed_road)
        if sum(1 for w in town.neighbours[at] if w != came_from) >= 2:
            found.add(at)
    return found
