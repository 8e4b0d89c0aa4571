"""How an episode drives an imported town's own SUMO net: the ego's route as the concatenation of
the model roads' edge lists, where on a road the ego stands, and which edge of a road its incident
is placed on.

A model road of an imported town runs along several SUMO edges (networks/real_net.py). The ego's
route is extended one model road ahead at the road's commit point, by the next road's whole edge
list; its position on a road is the start of the edge it is on along the road plus its position on
that edge (the junctions between the edges not counted, on both sides of the comparison). An
incident is placed on one edge of its road: the edge with the longest stretch the ego drives
before the road's commit point (ties: the first), with that edge's driving lane, its reverse edge
(where an oncoming vehicle comes from) and whether the net lets a vehicle overtake through the
opposite lane there (docs/scenes.md, "Real maps"). Where the net forbids a turn the model allows,
the ego drives SUMO's shortest way from the end of its road to the start of the next (a detour
counted in neither road, logged).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from trustroute.harness.simulation.incidents.base import Scene
from trustroute.networks.real_net import EdgeLanes, RoadEdges

# What an incident needs of its edge: a truck an edge the other way, a pedestrian that and a
# sidewalk on both (and a crossing at the edge's start, pedestrian.inject).
NEEDS_REVERSE = ("truck", "pedestrian")


@dataclass(frozen=True)
class IncidentPlace:
    """The edge of a road an incident is placed on, how far into the road the edge starts, and how
    much of it the ego drives before the road's commit point."""

    edge: EdgeLanes
    offset: float
    watched: float


class RealRoads:
    """The model roads of an imported town as SUMO edges, for one episode."""

    def __init__(self, roads: dict[str, RoadEdges], commit_distance: float) -> None:
        self.roads = roads
        self.commit_distance = commit_distance
        # The junctions inside a road count as part of it: a short edge between two of them can be
        # passed within one step, so the ego may never be seen on it.
        self._offsets = {road: {**dict(value.inner_junctions()),
                                **dict(zip(value.ids, value.offsets, strict=True))}
                         for road, value in roads.items()}

    def length(self, road: str) -> float:
        return self.roads[road].length

    def offsets(self, road: str) -> dict[str, float]:
        """Edge id (internal edges of the junctions inside the road included) -> where the edge
        starts along the road."""
        return self._offsets[road]

    def chain(self, road: str) -> tuple[str, ...]:
        """The SUMO edges `road` runs along, in driving order."""
        return self.roads[road].ids

    def edges(self) -> set[str]:
        """Every edge the town's roads run along."""
        return {edge for value in self.roads.values() for edge in value.ids}

    def start(self, road: str, position: float) -> tuple[list[str], float]:
        """The ego's first route (the start road's edges from the one holding `position` metres into
        the road) and its depart position on that edge."""
        value = self.roads[road]
        index = max(i for i, offset in enumerate(value.offsets) if offset <= position or i == 0)
        depart = min(position - value.offsets[index], value.edges[index].length)
        return list(value.ids[index:]), max(0.0, depart)

    def extend_route(self, sumo, vehicle_id: str, road: str, nxt: str) -> list[str]:
        """The ego's route: what is left of it, then the next road's edges. Where the net has no
        connection from `road`'s last edge to `nxt`'s first (a turn the net forbids and the model,
        which has no turn restrictions, allows), SUMO's shortest way between the two is driven in
        between. Returns the edges of that way ([] when connected)."""
        route = sumo.vehicle.getRoute(vehicle_id)
        index = sumo.vehicle.getRouteIndex(vehicle_id)
        last, first = self.roads[road].edges[-1], self.roads[nxt].ids[0]
        detour: list[str] = []
        if first not in last.successors:
            way = list(sumo.simulation.findRoute(last.edge, first).edges)
            if not way:
                raise RuntimeError(f"the net has no way from {road} into {nxt} (its connections forbid "
                                   "what the town's moves allow): re-import the town from a net without "
                                   "such turn restrictions")
            detour = way[1:-1]
        sumo.vehicle.setRoute(vehicle_id, [*route[max(index, 0):], *detour, *self.roads[nxt].ids])
        return detour

    def incident_place(self, road: str) -> IncidentPlace:
        value = self.roads[road]
        observed = value.length - self.commit_distance
        best = None
        for edge, offset in zip(value.edges, value.offsets, strict=True):
            watched = max(0.0, min(edge.length, observed - offset))
            if best is None or watched > best.watched:
                best = IncidentPlace(edge=edge, offset=offset, watched=watched)
        assert best is not None   # a road has at least one edge (networks/real_net.py)
        return best


def real_scene(real: RealRoads, road: str, kind: str, scene: Scene) -> Scene | None:
    """`scene` (given for the whole model road) moved onto the edge its incident is placed on, or
    None when the incident cannot be placed on this net: a truck or a pedestrian on a road without
    an edge the other way, a pedestrian without sidewalks (docs/scenes.md, "Real maps")."""
    place = real.incident_place(road)
    edge = place.edge
    if kind in NEEDS_REVERSE and edge.reverse_edge is None:
        return None
    if kind == "pedestrian" and not (edge.sidewalk and edge.reverse_sidewalk):
        return None
    return replace(scene, road=edge.edge, reverse_road=edge.reverse_edge, road_length=edge.length,
                   ego_distance=scene.ego_distance + place.offset, observed_length=place.watched,
                   lane=edge.driving_lane, lanes=edge.passenger_lanes, reverse_lane=edge.reverse_lane,
                   overtake=edge.overtake, end_junction=edge.end_junction,
                   start_junction=edge.start_junction)
