"""The warm-up drive of a live study: a route and incidents of its own, so that it rehearses no trial.

A participant's warm-up starts on the start road of their first trial's spec (with that trial's
driver model and SUMO's seeds of the warm-up: harness/live/server.py, `warm_up_task`), then
follows a route drawn at random through the town, WARM_UP_ROADS roads long (at each junction one
of the legal moves, not back where it came from when there is another), and meets on each of
those roads an incident drawn from the town's own mix of incidents (the kinds of its roads, as
often as they occur). Both draws come from one Generator seeded by
SeedSequence(study seed, spawn_key=(WARM_UP_KEY, participant, 1)): the same participant of the
same study always gets the same warm-up, every participant another one. The trials' routes are the
policies' and their incidents the town's; the warm-up's are neither.

The vehicle is driven along the drawn route by `DrawnRoute` (a routing policy that declares the
episode over at the route's end) on the town with the drawn incidents (`DrawnTown`: the town's
SUMO net, since the town's identity is unchanged, with `incident(road)` the drawn kind). Its spec
is the trial's start with a formula the drive never decides (`undecided_spec`): the trial's own
could accept or reject on a road of the drawn route and end the warm-up there. The warm-up is not
part of the dataset (its part goes to live/warmup/parts/).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from trustroute.harness.simulation.episode import EpisodeOptions, SumoEpisode
from trustroute.harness.simulation.stepping import run_to_end
from trustroute.harness.simulation.sumo_start import SumoConfig
from trustroute.harness.study.context import StudyContext
from trustroute.networks.road import Road
from trustroute.networks.sumo_net import pedestrian_roads
from trustroute.networks.town import NO_INCIDENT, Town
from trustroute.policies.logic.spec import Spec, spec_from_text
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

WARM_UP_ROADS = 6      # roads after the start road
WARM_UP_KEY = 4        # the spawn key of the warm-up's draws (as its seeds: server.WARM_UP_KEY)
ROUTE_STREAM = 1       # ... and of its route and incidents


@dataclass(frozen=True)
class DrawnTown(Town):
    """The town with the warm-up's incidents: `incident(road)` is the drawn kind (none off the
    route); its identity (content_hash, hence its SUMO net) is the town's."""

    drawn: dict[str, str] = field(default_factory=dict, compare=False)

    def incident(self, directed_road: str) -> str:
        return self.drawn.get(directed_road, NO_INCIDENT)


class DrawnRoute(RoutingPolicy):
    """Drive the drawn route; the episode is over at its last road."""

    name = "warm-up"

    def __init__(self, route: tuple[str, ...]) -> None:
        self.route = route

    def next_junction(self, context: DecisionContext) -> str:
        return Road.parse(self.route[len(context.route)]).to_junction

    def finished(self, context: DecisionContext) -> bool:
        return len(context.route) >= len(self.route)


def warm_up_rng(study_seed: int, participant: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(study_seed, spawn_key=(WARM_UP_KEY, participant,
                                                                                ROUTE_STREAM)))


def draw_route(town: Town, start: str, rng: np.random.Generator,
               roads: int = WARM_UP_ROADS) -> tuple[str, ...]:
    """The start road, then `roads` roads, each a legal move from the last (no U-turn when there
    is another move)."""
    route = [start]
    for _ in range(roads):
        here = route[-1]
        back = Road.parse(here).reverse.id
        moves = [town.successor(here, junction) for junction in town.actions(here)]
        onward = [road for road in moves if road != back] or moves
        route.append(onward[int(rng.integers(len(onward)))])
    return tuple(route)


def draw_incidents(town: Town, route: tuple[str, ...], rng: np.random.Generator) -> dict[str, str]:
    """An incident for each road after the start, drawn from the town's own mix of incidents; a
    pedestrian only where the town's SUMO net has its crossing (the roads with a pedestrian
    incident in the town)."""
    crossings = {frozenset(pair) for pair in pedestrian_roads(town)}
    mix = [town.incidents[road] for road in town.states]
    drawn = {}
    for road in route[1:]:
        crossed = frozenset(Road.parse(road)) in crossings
        kinds = [kind for kind in mix if kind != "pedestrian" or crossed]
        drawn[road] = str(kinds[int(rng.integers(len(kinds)))])
    return drawn


def warm_up_plan(town: Town, start: str, study_seed: int, participant: int) -> tuple[tuple[str, ...], dict]:
    """(route, incidents) of a participant's warm-up."""
    rng = warm_up_rng(study_seed, participant)
    route = draw_route(town, start, rng)
    return route, draw_incidents(town, route, rng)


def undecided_spec(spec: Spec, town: Town, route: tuple[str, ...]) -> Spec:
    """`spec`'s start with the formula `F off`, `off` a road of the town the drawn `route` does not
    take: its DFA neither accepts nor rejects on the route, so the episode ends at the route's end
    ("destination"). `spec` itself in a town whose every road is on the route."""
    off = next((road for road in town.states if road not in route), None)
    if off is None:
        return spec
    return spec_from_text(f'name = "warm-up"\nstart = "{spec.start}"\nformula = "F off"\n\n'
                          f'[states]\noff = ["{off}"]\n', f"{spec.source_path} (warm-up)", town)


def run_warm_up(context: StudyContext, task, driver, observer, person=None, sumo_config=None):
    """The warm-up episode `task` (server.warm_up_task) of the study whose context is `context`, on
    its drawn route and incidents, with the remote `driver` (and `person`, their controls at the
    wheel, and SUMO's settings, as run_planned_episode takes them); the EpisodeRecord."""
    config = context.config
    setup = context.setup(task.spec, task.condition)
    town = setup.town
    route, incidents = warm_up_plan(town, setup.spec.start, config.seed, task.participant)
    drawn = DrawnTown(**{f.name: getattr(town, f.name) for f in fields(Town) if f.init}, drawn=incidents)
    sumo_config = replace(sumo_config if sumo_config is not None else SumoConfig(),
                          background_vehicles=config.background_vehicles, route_files=tuple(config.routes))
    options = EpisodeOptions(config=sumo_config, observer=observer, person=person)
    spec = undecided_spec(setup.spec, town, route)
    warm_up = replace(setup, town=drawn, spec=spec, junction_cap=len(route))
    return run_to_end(SumoEpisode(warm_up, DrawnRoute(route), driver, task.episode_id, task.seed, options))
