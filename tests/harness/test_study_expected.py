"""A study's expected values are the certified [lower, upper] that `trustroute evaluate` reports
for the same policy and settings (policies/synthesis/rounding.py, `certify`), not the unrounded
sums: the analysis shows them as an interval beside the synthesized bounds."""

from __future__ import annotations

from trustroute.harness.study.config import load_study_config


def test_expected_values_are_evaluate_s_certified_bracket(tmp_path):
    from trustroute.app.synthesis import evaluate_single
    from trustroute.harness.study.context import study_context
    from trustroute.harness.study.expected import expected_values
    from trustroute.policies.belief.problem import problem
    from trustroute.policies.evaluation.settings import EvaluationSettings
    from trustroute.policies.evaluation.trust_state import evaluate_joint

    path = tmp_path / "study.toml"
    path.write_text("""[study]
participants = 2
seed = 5
engine = "model"
specs = ["phi1"]
conditions = ["free"]
horizon = 3
""")
    config = load_study_config(path)
    context = study_context(config)
    entry = expected_values(context)["phi1"]["free"]
    spec, policy = context.setup("phi1", "free").spec, context.policies[("phi1", "free")]
    settings = EvaluationSettings(fallback_after=config.fallback_after, max_junctions=config.junction_cap)
    found = problem(context.town, context.nominal, spec)
    reported = evaluate_single(found, policy, settings)
    computed = evaluate_joint(found.pomdp, spec, policy, settings)
    assert 0.0 < reported.lower < computed.lower <= computed.upper < reported.upper
    assert (entry["exact_lower"], entry["exact_upper"]) == (reported.lower, reported.upper)
