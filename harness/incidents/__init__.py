"""Incidents as SUMO events, one module per kind behind one interface (base.Incident).

`inject(kind, sumo, scene)` creates the SUMO objects of an incident on the road of `scene`
(or schedules them: a late pedestrian, an oncoming truck that enters later); "none" creates
nothing (returns None). The runner asks each live incident when it is in view, steps it, lets
it add its measures to the road's performance, and removes it when the ego leaves its road.
The scenes are described, with their distributions, in docs/scenes.md.
"""

from __future__ import annotations

from trustroute.harness.incidents import obstacle, oncoming, pedestrian, truck
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
    oncoming.define_type(sumo)
    truck.define_type(sumo)


def inject(kind: str, sumo, scene: Scene) -> Incident | None:
    if kind == "none":
        return None
    if kind not in INJECTORS:
        raise ValueError(f"unknown incident kind {kind!r}; known: {', '.join(sorted(INJECTORS))}, none")
    return INJECTORS[kind](sumo, scene)
