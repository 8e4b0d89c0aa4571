"""How an exact evaluation unfolds an episode tree: one frozen settings object, checked once where
it is made and passed to `plain.evaluate`, `trust_state.evaluate_joint` and their unfoldings."""

from __future__ import annotations

from dataclasses import dataclass

from trustroute.core import defaults
from trustroute.core.ranges import FALLBACK_AFTER, MAX_JUNCTIONS, MAX_NODES, keep_checked
from trustroute.policies.model.trust_pomdp import BeliefRule, checked_belief_rule
from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER


@dataclass(frozen=True)
class EvaluationSettings:
    """fallback_after: wrap the policy with the study's fallback after that many junctions (None:
    evaluate the policy as given). max_junctions: the episode's hard cap. belief_rule: the AV's
    filter ("bayes" or the authors' "paper" update). prune_below / max_nodes: branches below this
    probability, or beyond this frontier size, are not followed (None: the defaults of the
    unfolding the spec goes to, policies/evaluation/ledgers.py and trust_state.py). merge: merge
    the histories a policy reads alike (trust-state unfolding). time_limit: seconds after which
    open branches are cut (trust-state unfolding; None: no limit)."""

    fallback_after: int | None = DEFAULT_FALLBACK_AFTER
    max_junctions: int = DEFAULT_JUNCTION_CAP
    belief_rule: BeliefRule = defaults.BELIEF_RULE
    prune_below: float | None = None
    max_nodes: int | None = None
    merge: bool = True
    time_limit: float | None = None

    def __post_init__(self) -> None:
        """Each setting checked as every door takes it (trustroute/core/ranges.py): an InputError
        naming its option (the API's messages say its keyword). The time limit is checked at the
        doors (`check_time_limit`): inside a run it is the time left, which may be 0."""
        checked_belief_rule(self.belief_rule)
        keep_checked(self, {"max_junctions": MAX_JUNCTIONS, "fallback_after": FALLBACK_AFTER,
                            "max_nodes": MAX_NODES}, optional=("fallback_after", "max_nodes"))


DEFAULT_EVALUATION = EvaluationSettings()
