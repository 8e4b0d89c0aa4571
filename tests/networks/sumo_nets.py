"""Small hand-made SUMO nets for the import tests, built with netconvert from plain XML, and an
independent count of their decision junctions read straight from sumolib's node objects."""

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
                    allow: dict[tuple[str, str], str] | None = None) -> Path:
    """`name.net.xml` from nodes and edges; edge ids are `U_V`. `allow` gives an edge's vClasses."""
    allow = allow or {}
    node_xml = "".join(f'<node id="{n}" x="{x}" y="{y}" type="priority"/>' for n, (x, y) in nodes.items())
    edges = [(u, v) for a, b in two_way for u, v in ((a, b), (b, a))] + list(one_way)
    edge_xml = "".join(
        f'<edge id="{u}_{v}" from="{u}" to="{v}" numLanes="1" speed="13.89"'
        + (f' allow="{allow[(u, v)]}"' if (u, v) in allow else "") + "/>" for u, v in edges)
    (folder / f"{name}.nod.xml").write_text(f"<nodes>{node_xml}</nodes>")
    (folder / f"{name}.edg.xml").write_text(f"<edges>{edge_xml}</edges>")
    output = folder / f"{name}.net.xml"
    subprocess.run([find_binary("netconvert"), "-n", str(folder / f"{name}.nod.xml"),
                    "-e", str(folder / f"{name}.edg.xml"), "-o", str(output), "--no-warnings"],
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
