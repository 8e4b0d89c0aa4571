"""A SUMO net as a town: the decision-point graph of the roads a passenger car may use.

The net's edges that allow `passenger` (internal and other special edges left out) form a directed
graph on its junctions; only its largest strongly connected part is kept. A junction is a
*decision point* when a car arriving on one of its edges has a choice of next edge, the edge back to
where it came from not counted, as in the town's rule for moves (docs/model.md); a junction where
an arriving car must turn back (a dead end) ends roads too. Every other junction is passed without
a choice, so the chains of edges through such junctions collapse into one road of the model, with
their summed length and concatenated shape. Where two chains would join the same two junctions in
the same direction (or a chain would return to its start), a junction in the middle of the chain
becomes a junction of the town as well, so every road keeps its own name `U-V`.

Turns follow the net's connections: a car on a road may take a next road when a connection for a
passenger car (its lanes and the connection itself allowing `passenger`) leads from the road's last
edge into the next road's first, and every edge of a road leads into the next by such a connection.
The moves of a road are its connected next roads other than the way back; the way back only when
it is connected and nothing else is. Only the largest part of the roads in which every road can be
driven to and from every other along those moves is kept.

Names are stable: a junction is named after its SUMO id (characters other than letters, digits and
`_` become `_`; a long or clashing name is shortened and given a hash of the id), so importing the
same net twice gives the same town.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.networks.road import Road

PASSENGER = "passenger"
MAX_NAME = 64
UNSAFE = re.compile(r"[^A-Za-z0-9_]")
ROUND_METRES = 3  # digits kept of coordinates and lengths (SUMO writes two)


@dataclass(frozen=True)
class NetEdge:
    """One SUMO edge a passenger car may use: id, end junctions, driven length, shape, speed, name."""

    id: str
    source: str
    target: str
    length: float
    shape: tuple[tuple[float, float], ...]
    speed: float
    street: str


@dataclass(frozen=True)
class NetGraph:
    """The passenger graph of a net: junction positions and edges by id."""

    positions: dict[str, tuple[float, float]]
    edges: dict[str, NetEdge]
    dropped_edges: int  # normal edges a passenger car may not use
    connections: dict[str, frozenset[str]] = field(default_factory=dict)  # edge -> edges a car may enter


@dataclass(frozen=True)
class ImportedRoad:
    """One road of the model: a chain of SUMO edges from one town junction to the next."""

    source: str
    target: str
    edges: tuple[NetEdge, ...]

    @property
    def length(self) -> float:
        return round(sum(e.length for e in self.edges), ROUND_METRES)

    @property
    def speed(self) -> float:
        return max(e.speed for e in self.edges)

    @property
    def shape(self) -> tuple[tuple[float, float], ...]:
        points: list[tuple[float, float]] = []
        for edge in self.edges:
            for point in edge.shape:
                if not points or points[-1] != point:
                    points.append(point)
        return tuple(points)

    @property
    def street(self) -> str:
        names = [e.street for e in self.edges if e.street]
        return "; ".join(dict.fromkeys(names))


@dataclass(frozen=True)
class DecisionGraph:
    """The town of a net: junction name -> SUMO junction id, the roads, and what was left out."""

    junction_ids: dict[str, str]
    positions: dict[str, tuple[float, float]]
    roads: tuple[ImportedRoad, ...]  # source/target are junction names
    moves: dict[str, tuple[str, ...]] = field(default_factory=dict)  # road "U-V" -> next junctions W
    dropped: dict[str, int] = field(default_factory=dict)
    added_junctions: int = 0  # junctions without a choice that keep two roads' names apart

    def summary(self) -> str:
        parts = [f"{count} {what if count != 1 else DROPPED_ONE[what]}"
                 for what, count in self.dropped.items() if count]
        junctions = "junction" if self.added_junctions == 1 else "junctions"
        added = (f"; {self.added_junctions} {junctions} without a choice kept to tell parallel roads apart"
                 if self.added_junctions else "")
        return "dropped " + (", ".join(parts) if parts else "nothing") + added


# Each kind of DecisionGraph.dropped (its key, plural, is the --json's) with a count of one.
DROPPED_ONE = {
    "edges closed to passenger cars": "edge closed to passenger cars",
    "edges outside the largest strongly connected part": "edge outside the largest strongly connected part",
    "other strongly connected parts": "other strongly connected part",
    "edges only a U-turn reaches or parallel to a shorter one":
        "edge only a U-turn reaches or parallel to a shorter one",
    "roads the net's turns do not drive to and from the rest":
        "road the net's turns do not drive to and from the rest",
}


def _finite_points(points: Iterable[Iterable[float]], path: str,
                   place: str) -> tuple[tuple[float, float], ...]:
    out = tuple((float(p[0]), float(p[1])) for p in (tuple(q) for q in points))
    if not all(math.isfinite(c) for p in out for c in p):
        raise InputError(path, place, "the shape has coordinates that are not finite numbers (NaN or inf)",
                         "repair the net (e.g. rebuild it with netconvert) or remove the edge")
    return out


NET_FIX = "run `trustroute net build` or pass an existing .net.xml"


def require_net_file(net_path: str | Path, shown: str | None = None, fix: str = NET_FIX) -> None:
    """InputError unless the SUMO net is a file (sumolib and SUMO say less when it is not)."""
    if not Path(net_path).is_file():
        what = "path is not a file" if Path(net_path).exists() else "file does not exist"
        raise InputError(shown or str(net_path), "", f"the SUMO net {what}", fix)


READ_FIX = "pass an existing .net.xml(.gz) written by netconvert, or an .osm file"


def read_sumo_net(net_path: str | Path, shown: str | None = None, fix: str = READ_FIX):
    """The sumolib net of a `.net.xml` / `.net.xml.gz` (no internal edges), or an InputError naming
    the file when it is missing or unreadable (sumolib would raise its URL opener's or XML parser's
    error)."""
    import sumolib

    shown = shown or str(net_path)
    require_net_file(net_path, shown, fix)
    try:
        return sumolib.net.readNet(str(net_path), withInternal=False)
    except Exception as exc:  # sumolib raises what its XML parser raises
        raise InputError(shown, "", f"not a readable SUMO net ({type(exc).__name__}: {exc})", fix) from None


def read_net_graph(net_path: str | Path, shown: str | None = None) -> NetGraph:
    """The passenger graph of a SUMO `.net.xml` / `.net.xml.gz` read with sumolib."""
    shown = shown or str(net_path)
    net = read_sumo_net(net_path, shown)
    if not net.getNodes() and not net.getEdges(withInternal=False):
        # sumolib reads any XML without complaint: a route or additional file gives an empty net
        raise InputError(shown, "", "holds no SUMO net (no junction, no edge)",
                         "pass a .net.xml(.gz) written by netconvert (not a route, additional or "
                         "configuration file), or an .osm file")
    edges: dict[str, NetEdge] = {}
    connections: dict[str, frozenset[str]] = {}
    dropped = 0
    for edge in net.getEdges(withInternal=False):
        if edge.getFunction() != "":
            continue
        source, target = edge.getFromNode().getID(), edge.getToNode().getID()
        if not edge.allows(PASSENGER) or source == target:
            dropped += 1
            continue
        shape = _finite_points(edge.getShape(), shown, f"edge {edge.getID()}")
        edges[edge.getID()] = NetEdge(
            id=edge.getID(), source=source, target=target, length=float(edge.getLength()), shape=shape,
            speed=float(edge.getSpeed()), street=edge.getName() or "")
        connections[edge.getID()] = passenger_connections(edge)
    if not edges:
        raise InputError(shown, "", "the net has no road a passenger car may use",
                         "import a road network with streets open to cars (not a rail, bicycle or "
                         "pedestrian net)")
    positions = {}
    for node in net.getNodes():
        (point,) = _finite_points([node.getCoord()[:2]], shown, f"junction {node.getID()}")
        positions[node.getID()] = point
    return NetGraph(positions=positions, edges=edges, dropped_edges=dropped, connections=connections)


def passenger_connections(edge) -> frozenset[str]:
    """The edges a passenger car on sumolib edge `edge` may enter: some connection between them
    allows `passenger`, from a lane and into a lane that allow it."""
    return frozenset(
        to.getID() for to, links in edge.getOutgoing().items()
        if any(link.allows(PASSENGER) and link.getFromLane().allows(PASSENGER)
               and link.getToLane().allows(PASSENGER) for link in links))


def largest_strong_part(nodes: Iterable[str], edges: Iterable[NetEdge]) -> tuple[set[str], int]:
    """The junctions of the largest strongly connected part (ties: the part with the smallest
    junction id) and the number of strongly connected parts (iterative Kosaraju)."""
    nodes = sorted(set(nodes))
    forward: dict[str, list[str]] = {n: [] for n in nodes}
    backward: dict[str, list[str]] = {n: [] for n in nodes}
    for edge in edges:
        forward[edge.source].append(edge.target)
        backward[edge.target].append(edge.source)
    order: list[str] = []
    seen: set[str] = set()
    for root in nodes:
        if root in seen:
            continue
        seen.add(root)
        stack = [(root, iter(forward[root]))]
        while stack:
            node, successors = stack[-1]
            for nxt in successors:
                if nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, iter(forward[nxt])))
                    break
            else:
                stack.pop()
                order.append(node)
    assigned: set[str] = set()
    parts: list[set[str]] = []
    for root in reversed(order):
        if root in assigned:
            continue
        part = {root}
        assigned.add(root)
        stack2 = [root]
        while stack2:
            for prev in backward[stack2.pop()]:
                if prev not in assigned:
                    assigned.add(prev)
                    part.add(prev)
                    stack2.append(prev)
        parts.append(part)
    best = min(parts, key=lambda part: (-len(part), min(part)))
    return best, len(parts)


def onward(edge: NetEdge, out_edges: Mapping[str, list[NetEdge]]) -> list[NetEdge]:
    """The edges a car arriving on `edge` may take next, the one back to where it came from not
    counted (the town's rule for moves)."""
    return [e for e in out_edges[edge.target] if e.target != edge.source]


def decision_junctions(edges: Iterable[NetEdge], out_edges: Mapping[str, list[NetEdge]]) -> set[str]:
    """Junctions where an arriving car has a choice (two or more onward edges) or must turn back."""
    return {edge.target for edge in edges if len(onward(edge, out_edges)) != 1}


def _walk(first: NetEdge, ends: set[str], out_edges: Mapping[str, list[NetEdge]]) -> list[NetEdge] | str:
    """The chain of edges from `first` to the next town junction, or the junction to promote when
    the walk runs round a loop without one."""
    chain = [first]
    used = {first.id}
    while chain[-1].target not in ends:
        (nxt,) = onward(chain[-1], out_edges)
        if nxt.id in used:
            return min(e.target for e in chain)
        used.add(nxt.id)
        chain.append(nxt)
    return chain


def _chains(edges: list[NetEdge], ends: set[str], out_edges: Mapping[str, list[NetEdge]],
            ) -> tuple[list[list[NetEdge]], set[str]]:
    """Chains from every town junction and the junctions left to promote (a parallel single edge,
    with no junction in between to promote, is left out)."""
    by_pair: dict[tuple[str, str], list[list[NetEdge]]] = {}
    promote: set[str] = set()
    for edge in edges:
        if edge.source not in ends:
            continue
        walked = _walk(edge, ends, out_edges)
        if isinstance(walked, str):
            promote.add(walked)
            continue
        by_pair.setdefault((edge.source, walked[-1].target), []).append(walked)
    chains: list[list[NetEdge]] = []
    for (source, target), group in sorted(by_pair.items()):
        group.sort(key=lambda chain: (sum(e.length for e in chain), [e.id for e in chain]))
        for rank, chain in enumerate(group):
            if source != target and rank == 0:
                chains.append(chain)
            elif len(chain) > 1:
                promote.add(chain[(len(chain) - 2) // 2].target)
    return chains, promote


def collapse(edges: list[NetEdge]) -> tuple[list[list[NetEdge]], int]:
    """Chains between town junctions and how many junctions were added to keep road names apart."""
    out_edges: dict[str, list[NetEdge]] = {}
    for edge in sorted(edges, key=lambda e: e.id):
        out_edges.setdefault(edge.source, []).append(edge)
        out_edges.setdefault(edge.target, [])
    ends = decision_junctions(edges, out_edges)
    if not ends:
        ends = {min(out_edges)}  # a ring without a choice: start anywhere, the loop rule splits it
    added = 0
    while True:
        chains, promote = _chains(edges, ends, out_edges)
        promote -= ends
        if not promote:
            return chains, added
        ends |= promote
        added += len(promote)


def junction_names(ids: Iterable[str]) -> dict[str, str]:
    """SUMO junction id -> town junction name, stable and unique."""
    names: dict[str, str] = {}
    taken: set[str] = set()
    for sumo_id in sorted(ids):
        name = UNSAFE.sub("_", sumo_id) or "J"
        if len(name) > MAX_NAME or name in taken:
            digest = hashlib.sha256(sumo_id.encode()).hexdigest()[:10]
            name = f"{name[:MAX_NAME - 11]}_{digest}"
        names[sumo_id] = name
        taken.add(name)
    return names


def chain_moves(chains: list[list[NetEdge]], connections: Mapping[str, frozenset[str]]) -> list[list[int]]:
    """Per chain the indices of the chains a car may take next (the module's rule for turns): none
    when one of its own edges does not lead into the next."""
    starting: dict[str, list[int]] = {}
    for i, chain in enumerate(chains):
        starting.setdefault(chain[0].source, []).append(i)
    drivable = [all(b.id in connections.get(a.id, ()) for a, b in zip(chain, chain[1:], strict=False))
                for chain in chains]
    moves = []
    for i, chain in enumerate(chains):
        last = chain[-1]
        connected = [j for j in starting.get(last.target, []) if drivable[i] and drivable[j]
                     and chains[j][0].id in connections.get(last.id, ())]
        onward = [j for j in connected if chains[j][-1].target != chain[0].source]
        moves.append(onward or connected)
    return moves


def driven_part(chains: list[list[NetEdge]], moves: list[list[int]]) -> set[int]:
    """The chains of the largest part in which every chain reaches every other along the moves
    (ties: the part holding the smallest pair of SUMO junction ids)."""
    keys = [f"{chain[0].source} {chain[-1].target}" for chain in chains]
    arcs = [NetEdge(id="", source=keys[i], target=keys[j], length=0.0, shape=(), speed=0.0, street="")
            for i, targets in enumerate(moves) for j in targets]
    part, _ = largest_strong_part(keys, arcs)
    return {i for i, key in enumerate(keys) if key in part}


def decision_graph(graph: NetGraph, shown: str) -> DecisionGraph:
    """The town's junctions, roads and turns: the largest strongly connected part, collapsed."""
    edges = sorted(graph.edges.values(), key=lambda e: e.id)
    nodes = {n for e in edges for n in (e.source, e.target)}
    part, n_parts = largest_strong_part(nodes, edges)
    if len(part) < 2:
        raise InputError(shown, "", "no two junctions of the passenger roads can be driven to and from each "
                         "other (nothing strongly connected)", "import a net whose streets form a "
                         "connected network, not separate one-way pieces")
    kept = [e for e in edges if e.source in part and e.target in part]
    all_chains, added = collapse(kept)
    # Leaving out chains (parallel edges, edges only a U-turn reaches) and the turns the net forbids
    # can cut the town again: keep the part the moves drive to and from.
    moves = chain_moves(all_chains, graph.connections)
    driven = driven_part(all_chains, moves)
    chains = [c for i, c in enumerate(all_chains) if i in driven]
    core = {n for c in chains for n in (c[0].source, c[-1].target)}
    if len(chains) < 2:
        raise InputError(shown, "", "the turns the net's connections allow leave no two roads that can be "
                         "driven to and from each other", "import a larger part of the map, or a net "
                         "with turnarounds at its dead ends (netconvert without --no-turnarounds)")
    names = junction_names(core)
    roads = tuple(ImportedRoad(source=names[c[0].source], target=names[c[-1].target], edges=tuple(c))
                  for c in chains)
    used = {e.id for c in all_chains for e in c}
    dropped = {
        "edges closed to passenger cars": graph.dropped_edges,
        "edges outside the largest strongly connected part": len(edges) - len(kept),
        "other strongly connected parts": n_parts - 1,
        "edges only a U-turn reaches or parallel to a shorter one": len(kept) - len(used),
        "roads the net's turns do not drive to and from the rest": len(all_chains) - len(chains),
    }
    turns = {Road(names[c[0].source], names[c[-1].target]).id:
             tuple(sorted(names[all_chains[j][-1].target] for j in moves[i] if j in driven))
             for i, c in enumerate(all_chains) if i in driven}
    return DecisionGraph(
        junction_ids={names[n]: n for n in sorted(core)},
        positions={names[n]: graph.positions[n] for n in sorted(core)},
        roads=tuple(sorted(roads, key=lambda r: (r.source, r.target))),
        moves=dict(sorted(turns.items())),
        dropped=dropped,
        added_junctions=added,
    )
