"""Fixtures shared by the synthesis tests: exhaustive optima of the packaged specs and variants."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import pytest

from trustroute.policies.logic.spec import load_spec, spec_from_text
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.synthesis.exact_search import exact_optimum


@pytest.fixture(scope="session")
def packaged_optimum(pomdp: TrustPOMDP) -> Callable[..., float]:
    """optimum(name, horizon, belief_rule="bayes"): exact_optimum of specs/<name>.toml on the default
    POMDP, each computed once per session: the exhaustive search is exponential in the horizon
    (seconds at H = 8) and several modules check their bounds against the same few optima."""
    @functools.cache
    def optimum(name: str, horizon: int, belief_rule: BeliefRule = "bayes") -> float:
        return exact_optimum(pomdp, load_spec(f"specs/{name}.toml", pomdp.town), horizon, belief_rule)

    return optimum


@pytest.fixture(scope="session")
def strict_lowtrust_optimum(pomdp: TrustPOMDP) -> Callable[[float, int], float]:
    """optimum(offset, horizon): exact_optimum of specs/phi1_strict.toml with its lowtrust offset
    replaced, each computed once per session (the threshold tests here and the cluster-policy
    tests check their bounds at 2/7 and 3/7, H = 8, against the same optima)."""
    @functools.cache
    def optimum(offset: float, horizon: int) -> float:
        text = Path("specs/phi1_strict.toml").read_text()
        assert "offset = 0.3\n" in text
        spec = spec_from_text(text.replace("offset = 0.3\n", f"offset = {offset!r}\n"),
                              "<phi1_strict lowtrust offset>", pomdp.town)
        assert spec.belief_atoms["lowtrust"].offset == offset
        return exact_optimum(pomdp, spec, horizon)

    return optimum
