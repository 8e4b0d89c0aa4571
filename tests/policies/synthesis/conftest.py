"""Fixtures shared by the synthesis tests: exhaustive optima of the packaged specs."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.synthesis.exact_search import exact_optimum


@pytest.fixture(scope="session")
def packaged_optimum(pomdp: TrustPOMDP) -> Callable[..., float]:
    """optimum(name, horizon, belief_rule="bayes"): exact_optimum of specs/<name>.toml on the default
    POMDP, each computed once per session: the exhaustive search is exponential in the horizon
    (seconds at H = 8) and several modules check their bounds against the same few optima."""
    found: dict[tuple[str, int, BeliefRule], float] = {}

    def optimum(name: str, horizon: int, belief_rule: BeliefRule = "bayes") -> float:
        key = (name, horizon, belief_rule)
        if key not in found:
            spec = load_spec(f"specs/{name}.toml", pomdp.town)
            found[key] = exact_optimum(pomdp, spec, horizon, belief_rule)
        return found[key]

    return optimum
