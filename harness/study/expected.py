"""What a study's simulated rates are compared with: exact values and synthesized bounds.

For every (spec, condition) policy of a study: its exact satisfaction probability with the study's
fallback rule and junction cap (policies.evaluation.plain, for the nominal driver model: no sampling),
as `trustroute evaluate` reports it (rounded outward: policies/synthesis/rounding.py, `certify`), and
the [lower, upper] that synthesis certified for it (read from its policy file), stored in the
manifest by the runner and shown beside the simulated rates by the analysis.
"""

from __future__ import annotations

import time
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.context import StudyContext, aware_policy_path, belief_rule
from trustroute.policies.routing.protocol import RoutingPolicy


def expected_values(context: StudyContext) -> dict:
    """Exact value of each (spec, condition) policy of the study's context for the nominal driver
    (policies.evaluation.plain), and the synthesized bounds when the policy carries them."""
    from trustroute.policies.belief.problem import dfa_is_hidden
    from trustroute.policies.evaluation.settings import EvaluationSettings
    from trustroute.policies.evaluation.trust_state import evaluate_joint as evaluate
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.synthesis.rounding import certify, evaluation_rounding

    config = context.config
    pomdp = build_pomdp(context.town, context.nominal)
    condition_path = dict(zip(config.condition_names, config.conditions, strict=True))
    out: dict = {}
    for (spec_name, condition), policy in context.policies.items():
        started = time.perf_counter()
        setup = context.setup(spec_name, condition)
        # a condition whose AV filters with another model ("robust": the type-aware one) is
        # evaluated on its own filter with the nominal driver as the truth
        own = setup.driver_model is not context.nominal
        if own and dfa_is_hidden(setup.driver_model, setup.spec):
            # The joint unfolding's J is the law of the AV model's own hidden state: a true driver
            # other than that model is not evaluated for specs that test the hidden trust.
            out.setdefault(spec_name, {})[condition] = not_evaluated(
                policy, condition_path.get(condition), context, spec_name, config, started)
            continue
        value = evaluate(
            build_pomdp(context.town, setup.driver_model) if own else pomdp,
            setup.spec,
            policy,
            EvaluationSettings(fallback_after=config.fallback_after, max_junctions=config.junction_cap,
                               belief_rule=belief_rule(config)),
            truth=pomdp if own else None,
        )
        # reported as `trustroute evaluate` reports it: rounded outward for the nominal driver's
        # constants, whose posterior gives the probabilities (a hidden DFA state: its own model's)
        value = certify(value, evaluation_rounding(pomdp, setup.spec,
                                                   dfa_is_hidden(setup.driver_model, setup.spec)))
        entry: dict[str, float | None] = {
            "exact_lower": value.lower,
            "exact_upper": value.upper,
            "expected_final_trust": value.expected_final_trust,
            "fallback_probability": value.fallback_probability,
            "seconds": time.perf_counter() - started,
        }
        bounds = synthesized_bounds(policy, condition_path.get(condition), context, spec_name, config)
        if bounds is not None:
            entry["synthesized_lower"], entry["synthesized_upper"] = bounds[0], bounds[1]
            entry["synthesized_horizon"] = bounds[2]
        mark_fallback_only(entry, policy)
        out.setdefault(spec_name, {})[condition] = entry
    return out


def mark_fallback_only(entry: dict, policy: RoutingPolicy) -> None:
    """`entry["fallback_only"]`: what drives, when the condition's synthesized policy has no decision
    row (policies/routing/decision_tables.py); the key only then."""
    from trustroute.policies.routing.decision_tables import fallback_only

    fallback = fallback_only(policy)
    if fallback is not None:
        entry["fallback_only"] = fallback


def fallback_only_warnings(expected: dict) -> list[str]:
    """One line per (spec, condition) whose policy is only its fallback (`mark_fallback_only`)."""
    return [f"warning: the {condition} policy for {spec} has no synthesized decision (0 rows): it is "
            f"only its fallback, {entry['fallback_only']}; this condition measures that fallback"
            for spec, conditions in expected.items() for condition, entry in conditions.items()
            if entry.get("fallback_only")]


def not_evaluated(policy: RoutingPolicy, condition: str | None, context: StudyContext, spec_name: str,
                  config: StudyConfig, started: float) -> dict:
    """The entry of a policy whose exact value for the nominal driver is not computed (the exact
    value: None), with the bounds synthesis certified for it under its own model."""
    entry: dict[str, float | str | None] = {
        "exact_lower": None, "exact_upper": None, "expected_final_trust": None, "fallback_probability": None,
        "not_evaluated": "the spec tests the hidden trust and the policy's AV filters with another model "
                         "than the nominal driver's",
        "seconds": time.perf_counter() - started}
    bounds = synthesized_bounds(policy, condition, context, spec_name, config)
    if bounds is not None:
        entry["synthesized_lower"], entry["synthesized_upper"] = bounds[0], bounds[1]
        entry["synthesized_horizon"] = bounds[2]
    mark_fallback_only(entry, policy)
    return entry


def synthesized_bounds(
    policy: RoutingPolicy, condition: str | None, context: StudyContext, spec_name: str, config: StudyConfig
) -> tuple[float, float, int | None] | None:
    """[lower, upper] (and horizon) that synthesis certified for this policy: from the policy
    file ("aware": the resolver's cache entry), else the policy's certified_bounds(); None if unknown."""
    if condition is not None and condition != "free":
        try:
            from trustroute.policies.routing.files import read_policy_document

            if condition == "aware":
                path = aware_policy_path(context.town, context.nominal, context.specs[spec_name], config)
            else:
                path = Path(condition)
            document = read_policy_document(path)
            if document.get("lower") is not None and document.get("upper") is not None:
                return float(document["lower"]), float(document["upper"]), document.get("horizon")
        except (OSError, InputError, ValueError, KeyError):
            pass
    bounds = policy.certified_bounds()
    return None if bounds is None else (bounds[0], bounds[1], None)
