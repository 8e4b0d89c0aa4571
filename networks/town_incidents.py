"""The incidents of an imported town: read from a file, or drawn by a seeded rule.

File (`--incidents FILE`): a JSON object whose keys are roads of the town (`"U-V"`) or SUMO edge ids
(the entry then holds for the road that runs along that edge), and whose values are incident types;
roads not named get `none`.

Rule (`--incident-seed N`, docs/formats/town.md): roads are visited in sorted order and each takes
exactly two draws from the passed-in generator. The first decides whether the road has an
incident, with probability 1 - exp(-length / INCIDENT_SPACING): about one incident per
INCIDENT_SPACING metres of road, and never certain. The second picks the type by the road's class:
an arterial road (fastest edge above ARTERIAL_SPEED) mostly meets trucks, a local street mostly
pedestrians (TYPE_WEIGHTS).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.validation import parse_json, read_text
from trustroute.core.wording import shown_value
from trustroute.networks.town import INCIDENT_TYPES, NO_INCIDENT

INCIDENT_SPACING = 500.0  # metres of road per incident, on average
ARTERIAL_SPEED = 50 / 3.6  # m/s: faster roads are arterial
TYPE_WEIGHTS: dict[str, tuple[tuple[str, float], ...]] = {
    "arterial": (("truck", 0.5), ("obstacle", 0.4), ("pedestrian", 0.1)),
    "local": (("pedestrian", 0.5), ("obstacle", 0.3), ("truck", 0.2)),
}


@dataclass(frozen=True)
class RoadFacts:
    """What the rule needs of a road: its name, driven length (m), top speed (m/s), SUMO edges."""

    name: str
    length: float
    speed: float
    edges: tuple[str, ...] = ()


def road_class(road: RoadFacts) -> str:
    return "arterial" if road.speed > ARTERIAL_SPEED else "local"


def draw_incidents(roads: Sequence[RoadFacts], rng: np.random.Generator) -> dict[str, str]:
    """Incidents by the documented rule, every draw from `rng`."""
    out = {}
    for road in sorted(roads, key=lambda r: r.name):
        present = rng.random() < 1.0 - math.exp(-road.length / INCIDENT_SPACING)
        pick = rng.random()
        out[road.name] = incident_type(TYPE_WEIGHTS[road_class(road)], pick) if present else NO_INCIDENT
    return out


def incident_type(weights: Sequence[tuple[str, float]], pick: float) -> str:
    """The type whose share of the cumulative weights holds `pick` (uniform in [0, 1))."""
    total = 0.0
    for kind, weight in weights:
        total += weight
        if pick < total:
            return kind
    return weights[-1][0]


def incidents_from_file(path: str, roads: Sequence[RoadFacts]) -> dict[str, str]:
    """Incidents named in a file by road or by SUMO edge id; the other roads get none."""
    data = parse_json(read_text(path, path, "the incidents file", "pass an existing JSON file"), path,
                      "incidents file")
    if not isinstance(data, dict):
        raise InputError(path, "", "expected an object of road or SUMO edge id -> incident type",
                         "write {\"U-V\": \"truck\", \"edge_id\": \"pedestrian\"}")
    # An edge after a merge lies on every road that merges there: its entry holds for all of them.
    by_edge: dict[str, list[str]] = {}
    for road in roads:
        for edge in road.edges:
            by_edge.setdefault(edge, []).append(road.name)
    names = {road.name for road in roads}
    out = {road.name: NO_INCIDENT for road in roads}
    for key, kind in data.items():
        targets = [key] if key in names else by_edge.get(key, [])
        if not targets:
            raise InputError(path, key, "neither a road of the imported town nor a SUMO edge id of its roads",
                             "name a road as \"U-V\" (see the imported town) or an edge of the net")
        if kind not in INCIDENT_TYPES:
            raise InputError(path, key, f"unknown incident type {shown_value(kind)}",
                             f"use one of {', '.join(INCIDENT_TYPES)}")
        out.update(dict.fromkeys(targets, kind))
    return out
