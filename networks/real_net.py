"""The SUMO net an imported town drives: per model road its edges and the lanes its incidents use.

A town imported by `trustroute town import` (one with `sumo_net`) is driven on its source net, not
on a net built from its junctions. Each directed road of the model runs along the SUMO edges listed
in its geometry (`geometry[road].edges`, docs/formats/town.md); this module reads the net once
with sumolib and gives, for every road, those edges with their lengths and the lanes an incident
on an edge uses:

- the edge's *driving lane*: its rightmost lane a passenger car may use (where an obstacle stands);
- its *reverse edge* (where an oncoming vehicle drives): the edge whose lane netconvert declared
  the edge's opposite-direction neighbour (`<neigh>`, written by `--opposites.guess`); else, of
  the edges of the model road the other way (and any edge from the edge's end junction back to its
  start), the one whose ends lie nearest the edge's ends swapped (the two directions of a street
  are often cut into edges at different places), when they lie within the edge's length;
- whether a vehicle may *overtake through the opposite lane* there: only where that `<neigh>`
  exists, since SUMO overtakes through an oncoming lane only then;
- whether it and its reverse edge have sidewalks (lane 0 for pedestrians only), where a
  pedestrian scene can stand;
- the edges its connections lead to: a town imported with its turns (`turns`, docs/formats/town.md)
  has a connection for every move; one written without them may allow a move the net has no
  connection for (harness/simulation/real_roads.py then drives SUMO's shortest way round).

The town's net is checked against its recorded SHA-256 first (road_geometry.check_sumo_net).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.networks.road import Road
from trustroute.networks.road_geometry import check_sumo_net
from trustroute.networks.sumo_import import read_sumo_net
from trustroute.networks.town import Town

PASSENGER = "passenger"


@dataclass(frozen=True)
class EdgeLanes:
    """One SUMO edge as an incident sees it."""

    edge: str
    length: float                 # metres, its driving lane's length
    driving_lane: int             # index of its rightmost lane open to passenger cars
    passenger_lanes: int          # how many of its lanes are open to passenger cars
    start_junction: str
    end_junction: str
    reverse_edge: str | None      # an edge from end_junction back to start_junction, or None
    reverse_lane: int             # index of the reverse edge's leftmost passenger lane (the one nearest)
    overtake: bool                # the reverse lane is the declared opposite-direction neighbour
    successors: frozenset[str] = frozenset()   # edges a connection of the net leads to
    vias: tuple[tuple[str, str], ...] = ()      # (next edge, the internal edge leading to it)
    sidewalk: bool = False                      # its lane 0 is for pedestrians only
    reverse_sidewalk: bool = False              # ... and the reverse edge's


@dataclass(frozen=True)
class RoadEdges:
    """A model road as SUMO edges: ids in driving order, their lanes, and where each starts along
    the road (metres, the junctions between them not counted)."""

    road: str
    edges: tuple[EdgeLanes, ...]

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(edge.edge for edge in self.edges)

    def inner_junctions(self) -> tuple[tuple[str, float], ...]:
        """The internal edges between consecutive edges of the road (junctions passed without a
        choice) and where along the road each starts (the end of the edge before it)."""
        out = []
        for edge, nxt, offset in zip(self.edges, self.edges[1:], self.offsets, strict=False):
            via = dict(edge.vias).get(nxt.edge)
            if via is not None:
                out.append((via, offset + edge.length))
        return tuple(out)

    @property
    def offsets(self) -> tuple[float, ...]:
        out, total = [], 0.0
        for edge in self.edges:
            out.append(total)
            total += edge.length
        return tuple(out)

    @property
    def length(self) -> float:
        return sum(edge.length for edge in self.edges)


def is_imported(town: Town) -> bool:
    """A town driven on its own SUMO net (it records the net it was imported from)."""
    return town.sumo_net is not None


def town_net_file(town: Town) -> Path:
    """The imported town's net, its content checked against `sumo_net.sha256` (InputError: one
    line naming the town file and the fix)."""
    if town.sumo_net is None:
        raise ValueError("the town was not imported from a SUMO net")
    return check_sumo_net(town.sumo_net, town.source_path or ".")


def _is_sidewalk(edge) -> bool:
    lane = edge.getLanes()[0]
    return lane.allows("pedestrian") and not lane.allows(PASSENGER)


def _passenger_lanes(edge) -> list:
    return [lane for lane in edge.getLanes() if lane.allows(PASSENGER)]


def _mismatch(edge, other) -> float:
    """How far `other`'s ends lie from `edge`'s ends swapped (metres)."""
    return (math.dist(edge.getToNode().getCoord()[:2], other.getFromNode().getCoord()[:2])
            + math.dist(edge.getFromNode().getCoord()[:2], other.getToNode().getCoord()[:2]))


def _reverse_edge(net, edge, leftmost, other_way: list):
    """The edge an oncoming vehicle drives beside `edge`, and whether it is the declared opposite."""
    neigh = leftmost.getNeigh()   # the neighbour lane's id, or None
    if neigh is not None:
        declared = net.getEdge(neigh.rsplit("_", 1)[0])
        if declared.allows(PASSENGER):
            return declared, True
    start, end = edge.getFromNode(), edge.getToNode()
    candidates = {e.getID(): e for e in [*other_way, *end.getOutgoing()]
                  if e.getFunction() == "" and _passenger_lanes(e)
                  and (e.getToNode() is start or e in other_way)}
    ranked = sorted(candidates.values(), key=lambda e: (_mismatch(edge, e), e.getID()))
    if ranked and _mismatch(edge, ranked[0]) <= edge.getLength():
        return ranked[0], False
    return None, False


def _edge_lanes(net, edge, other_way: list) -> EdgeLanes:
    lanes = _passenger_lanes(edge)
    start, end = edge.getFromNode(), edge.getToNode()
    leftmost = lanes[-1] if lanes else edge.getLanes()[-1]
    reverse, declared = _reverse_edge(net, edge, leftmost, other_way)
    reverse_lane = _passenger_lanes(reverse)[-1].getIndex() if reverse is not None else 0
    return EdgeLanes(edge=edge.getID(), length=float((lanes[0] if lanes else leftmost).getLength()),
                     driving_lane=(lanes[0] if lanes else leftmost).getIndex(), passenger_lanes=len(lanes),
                     start_junction=start.getID(), end_junction=end.getID(),
                     reverse_edge=reverse.getID() if reverse is not None else None,
                     reverse_lane=reverse_lane, overtake=bool(declared),
                     successors=frozenset(e.getID() for e in edge.getOutgoing()),
                     sidewalk=_is_sidewalk(edge),
                     reverse_sidewalk=reverse is not None and _is_sidewalk(reverse),
                     vias=tuple(sorted((e.getID(), via.rsplit("_", 1)[0])
                                       for e, connections in edge.getOutgoing().items()
                                       for via in [connections[0].getViaLaneID()] if via)))


_ROADS: dict[tuple[str, str], dict[str, RoadEdges]] = {}


def road_edges(town: Town, net_file: Path) -> dict[str, RoadEdges]:
    """Every directed road of the imported town as its SUMO edges (read once per net and town in a
    process). A road without `edges`, or an edge the net lacks, is an InputError."""
    key = (str(net_file), town.content_hash)
    found = _ROADS.get(key)
    if found is not None:
        return found
    net = read_sumo_net(net_file, fix="pass the town's own net (its `sumo_net`) or re-import the town "
                        "with trustroute town import")
    out: dict[str, RoadEdges] = {}
    for road in town.states:
        other_way = town.geometry.get(Road.parse(road).reverse.id)
        reverse_edges = [net.getEdge(e) for e in (other_way.edges if other_way else ()) if net.hasEdge(e)]
        geometry = town.geometry.get(road)
        if geometry is None or not geometry.edges:
            raise InputError(town.source_path or "town", f"geometry.{road}.edges", "the road lists no SUMO "
                             "edges, so it cannot be driven on the town's net",
                             "re-import the town with trustroute town import")
        edges = []
        for edge_id in geometry.edges:
            if not net.hasEdge(edge_id):
                raise InputError(town.source_path or "town", f"geometry.{road}.edges",
                                 f"the net {net_file} has no edge {edge_id}",
                                 "re-import the town with trustroute town import")
            edges.append(_edge_lanes(net, net.getEdge(edge_id), reverse_edges))
        out[road] = RoadEdges(road=road, edges=tuple(edges))
    _ROADS[key] = out
    return out
