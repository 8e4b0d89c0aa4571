"""Incidents as SUMO events, one module per kind behind one interface (base.Incident).

`inject(kind, sumo, scene)` creates the SUMO objects of an incident on the road of `scene`;
"none" creates nothing (returns None). The runner asks each live incident when it is in view,
steps it, and removes it once the ego has passed it or leaves its road.
"""

from __future__ import annotations

from trustroute.harness.incidents import obstacle, pedestrian, truck
from trustroute.harness.incidents.base import EgoState, Incident, Scene

INJECTORS = {
    "pedestrian": pedestrian.inject,
    "obstacle": obstacle.inject,
    "truck": truck.inject,
}

__all__ = ["EgoState", "Incident", "Scene", "INJECTORS", "inject", "define_types"]


def define_types(sumo) -> None:
    """Vehicle and person types the incident kinds use (once per simulation)."""
    obstacle.define_type(sumo)
    truck.define_type(sumo)


def inject(kind: str, sumo, scene: Scene) -> Incident | None:
    if kind == "none":
        return None
    if kind not in INJECTORS:
        raise ValueError(f"unknown incident kind {kind!r}; known: {', '.join(sorted(INJECTORS))}, none")
    return INJECTORS[kind](sumo, scene)
