"""An episode as an object driven from outside, as sumo-rl's environments are: `advance()` runs it
to the next decision point (the AV must choose its next junction) or to its end, and
`choose(junction)` answers a decision point. The SUMO engine (episode.py `SumoEpisode`) and the
model engine (model_engine.py `ModelEpisode`) are stepped alike by the study runner
(`run_to_end`, which asks the episode's own routing policy), by a live study's worker (the same,
with a person at the wheel) and by the gym environment (gym_env.py, where the agent chooses).

The episode's rules stay the tracker's (episode_tracker.py, policies/routing/episode_rules.py): a
decision point is only offered where the DFA, the policy's destination and the junction cap have
not ended the episode, and a choice is checked legal and recorded with whether the fallback drove.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from trustroute.harness.simulation.episode_record import EpisodeRecord
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy


@dataclass(frozen=True, eq=False)
class DecisionPoint:
    """The AV is at its road's commit point and must choose the next junction: what it knows
    (`context`) and the junctions it may choose (`legal`, the town's moves from the road)."""

    context: DecisionContext
    legal: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class End:
    """The episode is over: its logs."""

    record: EpisodeRecord


class SteppableEpisode(Protocol):
    """One episode, stepped from outside."""

    @property
    def policy(self) -> RoutingPolicy:
        """The routing policy the episode's rules read (finished, fallback), with the fallback."""
        ...

    def advance(self) -> DecisionPoint | End:
        """Run to the next decision point, or to the end (then the same End on every call)."""
        ...

    def choose(self, junction: str) -> None:
        """The answer to the decision point `advance` returned (ValueError: not a legal move)."""
        ...

    def close(self) -> None:
        """Stop an episode that has not ended (its simulation is closed); nothing after an end."""
        ...


def run_to_end(episode: SteppableEpisode) -> EpisodeRecord:
    """The episode driven by its own routing policy, decision after decision: its logs."""
    try:
        point = episode.advance()
        while isinstance(point, DecisionPoint):
            episode.choose(episode.policy.next_junction(point.context))
            point = episode.advance()
    except BaseException:
        episode.close()
        raise
    return point.record
