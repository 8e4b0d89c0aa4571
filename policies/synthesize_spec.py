"""Synthesis for any spec: the one entry point callers use (docs/trust_states.md).

Specs whose formula tests the hidden trust go to policies/trust_state_synthesis/synthesis.py (search over
joint (trust, DFA state) beliefs); every other spec goes to policies/synthesis/search.py unchanged, so
its bounds and policy file are exactly those of `search.synthesize`
(tests/policies/test_synthesize_spec.py compares them byte for byte).
"""

from __future__ import annotations

from collections.abc import Callable

from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.synthesis.arguments import check_synthesis_arguments
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.result import SynthesisResult


def synthesize_spec(pomdp: TrustPOMDP, spec: Spec, tau: float = 1e-3, time_limit: float = 60.0,
                    horizon: int | None = None, belief_rule: BeliefRule = "bayes",
                    on_iteration: Callable[[float, float], None] | None = None,
                    clusters: str = "auto") -> SynthesisResult:
    """lower <= Pr_max(spec) <= upper and a policy whose value is at least lower (see `synthesize`;
    `clusters` applies to specs without trust-state atoms, docs/synthesis.md "Cluster policies")."""
    if spec.uses_trust_atoms:
        check_synthesis_arguments(tau, horizon, belief_rule)
        from trustroute.policies.trust_state_synthesis.synthesis import synthesize_joint

        return synthesize_joint(pomdp, spec, tau=tau, time_limit=time_limit, horizon=horizon,
                                belief_rule=belief_rule, on_iteration=on_iteration)
    return synthesize(pomdp, spec, tau=tau, time_limit=time_limit, horizon=horizon,
                      belief_rule=belief_rule, on_iteration=on_iteration, clusters=clusters)
