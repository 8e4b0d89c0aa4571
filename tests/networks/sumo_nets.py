"""Small hand-made SUMO nets for the import tests, built with netconvert from plain XML, and
independent counts read straight from sumolib's objects: the decision junctions, the moves a
passenger car may make, the moves of a route that have no connection."""

from __future__ import annotations

import subprocess
from pathlib import Path

import sumolib

from trustroute.networks.sumo_net import find_binary

# A square a-b-c-d with a centre e joined to every corner: every junction has three or more
# neighbours, so every one is a decision point.
WHEEL_NODES = {"a": (0, 0), "b": (300, 0), "c": (300, 300), "d": (0, 300), "e": (150, 150)}
WHEEL_ROADS = [("a", "b"), ("b", "c"), ("c", "d"), ("d", "a"),
               ("a", "e"), ("b", "e"), ("c", "e"), ("d", "e")]


def build_plain_net(folder: Path, name: str, nodes: dict[str, tuple[float, float]],
                    two_way: list[tuple[str, str]], one_way: list[tuple[str, str]] = (),
                    allow: dict[tuple[str, str], str] | None = None,
                    forbidden: list[tuple[str, str]] = (), turnarounds: bool = True) -> Path:
    """`name.net.xml` from nodes and edges; edge ids are `U_V`. `allow` gives an edge's vClasses;
    `forbidden` the (from edge, to edge) connections deleted (a plain connection file's `<delete>`);
    `turnarounds=False` builds without any U-turn connection."""
    allow = allow or {}
    node_xml = "".join(f'<node id="{n}" x="{x}" y="{y}" type="priority"/>' for n, (x, y) in nodes.items())
    edges = [(u, v) for a, b in two_way for u, v in ((a, b), (b, a))] + list(one_way)
    edge_xml = "".join(
        f'<edge id="{u}_{v}" from="{u}" to="{v}" numLanes="1" speed="13.89"'
        + (f' allow="{allow[(u, v)]}"' if (u, v) in allow else "") + "/>" for u, v in edges)
    (folder / f"{name}.nod.xml").write_text(f"<nodes>{node_xml}</nodes>")
    (folder / f"{name}.edg.xml").write_text(f"<edges>{edge_xml}</edges>")
    (folder / f"{name}.con.xml").write_text(
        "<connections>" + "".join(f'<delete from="{a}" to="{b}"/>' for a, b in forbidden) + "</connections>")
    output = folder / f"{name}.net.xml"
    subprocess.run([find_binary("netconvert"), "-n", str(folder / f"{name}.nod.xml"),
                    "-e", str(folder / f"{name}.edg.xml"), "-x", str(folder / f"{name}.con.xml"),
                    "-o", str(output), "--no-warnings", *([] if turnarounds else ["--no-turnarounds"])],
                   check=True, capture_output=True)
    return output


def passenger_edges(edges: list) -> list:
    return [e for e in edges if e.getFunction() == "" and e.allows("passenger")]


def sumolib_decision_junctions(net_path: Path) -> set[str]:
    """Junctions where a car arriving on some passenger edge has other than exactly one next edge,
    the edge back to where it came from not counted (the town's rule for moves)."""
    net = sumolib.net.readNet(str(net_path))
    found = set()
    for node in net.getNodes():
        outgoing = passenger_edges(node.getOutgoing())
        for edge in passenger_edges(node.getIncoming()):
            choices = [o for o in outgoing if o.getToNode() != edge.getFromNode()]
            if len(choices) != 1:
                found.add(node.getID())
    return found


def car_connected(net, from_edge: str, to_edge: str) -> bool:
    """sumolib: some connection from `from_edge` into `to_edge` a passenger car may drive."""
    links = net.getEdge(from_edge).getOutgoing().get(net.getEdge(to_edge), [])
    return any(link.allows("passenger") and link.getFromLane().allows("passenger")
               and link.getToLane().allows("passenger") for link in links)


def sumolib_moves(net_path: Path) -> dict[str, set[str]]:
    """For a net whose junctions are all decision points (every edge a road of the town): per
    passenger edge the edges a car may take next, the way back only where nothing else is
    connected."""
    net = sumolib.net.readNet(str(net_path))
    out = {}
    for edge in passenger_edges(net.getEdges()):
        connected = [o for o in passenger_edges(edge.getToNode().getOutgoing())
                     if car_connected(net, edge.getID(), o.getID())]
        onward = [o for o in connected if o.getToNode() != edge.getFromNode()]
        out[edge.getID()] = {o.getID() for o in (onward or connected)}
    return out


def unconnected_moves(town, net_path: Path) -> tuple[int, int]:
    """(moves of the town with no passenger connection in the net, all moves): a move is
    connected when the road's edges lead one into the next and its last edge into the next road's
    first."""
    net = sumolib.net.readNet(str(net_path))
    missing = total = 0
    for road in town.states:
        edges = town.geometry[road].edges
        inside = all(car_connected(net, a, b) for a, b in zip(edges, edges[1:], strict=False))
        for nxt in town.successors(road):
            total += 1
            missing += not (inside and car_connected(net, edges[-1], town.geometry[nxt].edges[0]))
    return missing, total
