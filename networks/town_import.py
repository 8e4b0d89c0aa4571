"""`trustroute town import`: a SUMO net or an OpenStreetMap extract written as a town file.

The steps: an OSM extract becomes a net (networks/osm_convert.py); the net's decision-point graph
(networks/sumo_import.py) gives the junctions and the roads, with their shapes, lengths, SUMO edges
and street names, and the turns the net's connections allow (written as `turns` for the roads
whose moves differ from the town's rule); incidents come from a file or the seeded rule
(networks/town_incidents.py). The town is validated as any town file is before anything is
written, then the net (for an OSM source) and the town are each written atomically, so a failed
import leaves no half-written file.
The output is the same bytes for the same source and options.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_bytes, atomic_write_text
from trustroute.networks.osm_convert import convert_osm, source_kind
from trustroute.networks.road import Road
from trustroute.networks.road_geometry import RoadGeometry, file_sha256
from trustroute.networks.sumo_import import ROUND_METRES, DecisionGraph, decision_graph, read_net_graph
from trustroute.networks.town import NO_INCIDENT, Town, rule_moves, town_from_dict
from trustroute.networks.town_incidents import RoadFacts, draw_incidents, incidents_from_file


@dataclass(frozen=True)
class TownImport:
    """What an import wrote and found."""

    town: Town
    town_path: Path
    net_path: Path
    graph: DecisionGraph
    incident_rule: str

    def to_dict(self) -> dict:
        one_way = len(self.town.one_way)
        return {"junctions": len(self.town.junctions), "roads": len(self.town.states),
                "one_way_roads": one_way, "two_way_roads": (len(self.town.states) - one_way) // 2,
                "restricted_roads": len(self.town.turns),
                "added_junctions": self.graph.added_junctions, "dropped": dict(self.graph.dropped),
                "incidents": self.incident_rule, "content_hash": self.town.content_hash}

    def summary(self) -> str:
        counts = self.to_dict()
        return (f"{counts['junctions']} junctions, {counts['roads']} directed roads "
                f"(two-way: {counts['two_way_roads']}, one-way: {counts['one_way_roads']}; "
                f"{counts['restricted_roads']} with turn restrictions)")


def default_net_path(town_path: Path) -> Path:
    """Where the net of an OSM import goes: beside the town, `town.json` -> `town.net.xml`."""
    return town_path.with_name(town_path.name.removesuffix(".json") + ".net.xml")


def _round(value: float) -> float:
    return round(value, ROUND_METRES)


def town_document(graph: DecisionGraph, incidents: dict[str, str], net_file: str, net_sha256: str,
                  provenance: str) -> dict:
    """The town file's content (docs/formats/town.md)."""
    directed = {(r.source, r.target) for r in graph.roads}
    pairs = sorted({tuple(sorted(pair)) for pair in directed})
    one_way = sorted([u, v] for u, v in directed if (v, u) not in directed)
    neighbours: dict[str, list[str]] = {}
    for u, v in sorted(directed):
        neighbours.setdefault(u, []).append(v)
    turns = {road: list(moves) for road, moves in graph.moves.items()
             if moves != rule_moves(neighbours, road)}
    geometry = {
        Road(r.source, r.target).id: RoadGeometry(
            shape=tuple((_round(x), _round(y)) for x, y in r.shape), length=r.length,
            edges=tuple(e.id for e in r.edges), street=r.street).to_dict()
        for r in graph.roads
    }
    return {
        "source": provenance,
        "junctions": {name: [_round(x), _round(y)] for name, (x, y) in sorted(graph.positions.items())},
        "roads": [list(pair) for pair in pairs],
        "one_way": one_way,
        "turns": turns,
        "incidents": dict(sorted(incidents.items())),
        "geometry": dict(sorted(geometry.items())),
        "sumo_net": {"file": net_file, "sha256": net_sha256},
    }


def town_json(document: dict) -> str:
    """The town as JSON with one line per junction, road, incident and geometry entry (a city's
    file stays readable and diffs line by line)."""
    def compact(value: object) -> str:
        return json.dumps(value, separators=(", ", ": "), ensure_ascii=False)

    blocks = []
    for key, value in document.items():
        if isinstance(value, dict) and value and key != "sumo_net":
            rows = [f"  {compact(k)}: {compact(v)}" for k, v in value.items()]
            blocks.append(f" {compact(key)}: {{\n" + ",\n".join(rows) + "\n }")
        elif isinstance(value, list) and value:
            rows = [f"  {compact(item)}" for item in value]
            blocks.append(f" {compact(key)}: [\n" + ",\n".join(rows) + "\n ]")
        else:
            blocks.append(f" {compact(key)}: {compact(value)}")
    return "{\n" + ",\n".join(blocks) + "\n}\n"


def road_facts(graph: DecisionGraph) -> list[RoadFacts]:
    return [RoadFacts(name=Road(r.source, r.target).id, length=r.length, speed=r.speed,
                      edges=tuple(e.id for e in r.edges)) for r in graph.roads]


def _net_reference(net_path: Path, town_path: Path) -> str:
    """The net's path relative to the town's folder when it lies in it (the two move together),
    else absolute."""
    net, folder = net_path.resolve(), town_path.resolve().parent
    return net.relative_to(folder).as_posix() if net.is_relative_to(folder) else str(net)


def import_town(source: str | Path, town_path: str | Path, incidents_path: str | None = None,
                rng: np.random.Generator | None = None, net_out: str | Path | None = None,
                incident_seed: int | None = None) -> TownImport:
    """Import `source` (.net.xml, .net.xml.gz or .osm) and write the town to `town_path`.
    Incidents: from `incidents_path`, else drawn with `rng` (its seed, for the provenance, in
    `incident_seed`), else none."""
    source, town_path = Path(source), Path(town_path)
    kind = source_kind(source)
    with tempfile.TemporaryDirectory(prefix="trustroute-import-") as work:
        if kind == "osm":
            net_bytes = convert_osm(source)
            net_path = Path(net_out) if net_out is not None else default_net_path(town_path)
            if not net_path.name.endswith(".net.xml"):
                raise InputError(str(net_path), "", "the converted net is written as plain XML",
                                 "name the net file ....net.xml")
            read_path = Path(work) / "osm.net.xml"
            read_path.write_bytes(net_bytes)
            graph = decision_graph(read_net_graph(read_path, str(source)), str(source))
            net_sha256 = file_sha256(read_path)
        else:
            net_bytes, net_path = None, source
            graph = decision_graph(read_net_graph(source), str(source))
            net_sha256 = file_sha256(source)
    facts = road_facts(graph)
    if incidents_path is not None:
        incidents, rule = incidents_from_file(incidents_path, facts), f"from {Path(incidents_path).name}"
    elif rng is not None:
        incidents, rule = draw_incidents(facts, rng), f"drawn by the seeded rule (seed {incident_seed})"
    else:
        incidents, rule = {fact.name: NO_INCIDENT for fact in facts}, "none"
    provenance = (f"imported by trustroute town import from {source.name} "
                  f"({'OpenStreetMap via netconvert' if kind == 'osm' else 'SUMO net'}); incidents {rule}")
    document = town_document(graph, incidents, _net_reference(net_path, town_path), net_sha256, provenance)
    text = town_json(document)
    town = town_from_dict(json.loads(text), str(town_path))
    if net_bytes is not None:
        atomic_write_bytes(net_path, net_bytes, "SUMO net")
    atomic_write_text(town_path, text, "town file")
    return TownImport(town=town, town_path=town_path, net_path=net_path, graph=graph, incident_rule=rule)
