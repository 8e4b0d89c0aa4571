"""Incidents as SUMO events, one module per kind behind one interface (base.Incident).

`inject(kind, sumo, scene)` creates the SUMO objects of an incident on the road of `scene`
(or schedules them: a late pedestrian, an oncoming truck that enters later); "none" creates
nothing (returns None). The runner asks each live incident when it is in view, steps it, lets
it add its measures to the road's performance, and removes it when the ego leaves its road.
The scenes are described, with their distributions, in docs/scenes.md.
"""

from __future__ import annotations

from collections.abc import Callable

from trustroute.harness.simulation.incidents import obstacle, oncoming, pedestrian, truck
from trustroute.harness.simulation.incidents.base import EgoState, Incident, Scene
from trustroute.harness.simulation.sumo_start import Sumo

TypeDefiner = Callable[[Sumo], None]

INJECTORS: dict[str, Callable[[Sumo, Scene], Incident | None]] = {
    "pedestrian": pedestrian.inject,
    "obstacle": obstacle.inject,
    "truck": truck.inject,
}

__all__ = ["EgoState", "Incident", "Scene", "INJECTORS", "inject", "define_types"]


# The SUMO types each kind's objects use.
TYPE_DEFINERS: dict[str, tuple[TypeDefiner, ...]] = {
    "pedestrian": (pedestrian.define_type,),
    "obstacle": (obstacle.define_type, oncoming.define_type),
    "truck": (oncoming.define_type, truck.define_type),
}


def define_types(sumo: Sumo) -> None:
    """Every vehicle and person type the incident kinds use (once per simulation)."""
    pedestrian.define_type(sumo)
    obstacle.define_type(sumo)
    oncoming.define_type(sumo)
    truck.define_type(sumo)


def inject(kind: str, sumo: Sumo, scene: Scene, defined: set[TypeDefiner] | None = None) -> Incident | None:
    """The incident of `kind` on scene.road. defined: the type definers already run in this
    simulation; the kind's missing types are defined first and added to it (an episode defines
    only the types of the kinds it meets, about 20 TraCI calls less on a route without them).
    None: the caller has run define_types."""
    if kind == "none":
        return None
    if kind not in INJECTORS:
        raise ValueError(f"unknown incident kind {kind!r}; known: {', '.join(sorted(INJECTORS))}, none")
    if defined is not None:
        for definer in TYPE_DEFINERS[kind]:
            if definer not in defined:
                definer(sumo)
                defined.add(definer)
    return INJECTORS[kind](sumo, scene)
