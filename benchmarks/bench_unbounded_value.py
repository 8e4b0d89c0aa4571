"""The unbounded φ1 with the trust atom (the peer table's row `paper_phi1_trust_unbounded`): our
bracket beside the peers' converged value 1 (docs/peers.md).

`trustroute synth`'s call (synthesize_spec, τ = 1e-3, 60 s, unbounded), then the returned policy
evaluated over unbounded time (evaluate_joint_table_unbounded) with 20,000, 50,000 and 200,000
nodes per level, 60 s each: how much of the missing mass is the per-level frontier's cut and how
much the time limit's.
"""

from __future__ import annotations

import time

PEER_VALUE = 1.0                  # Storm's [1, 1] and PAYNT's controller on this row
TIME_LIMIT = 60.0
FRONTIERS = (20_000, 50_000, 200_000)


def run() -> list[dict]:
    from benchmarks.bench_peers import problem
    from trustroute.policies.evaluation.trust_state import evaluate_joint_table_unbounded
    from trustroute.policies.synthesis.rounding import widen
    from trustroute.policies.synthesis.settings import SynthesisSettings
    from trustroute.policies.synthesize_spec import synthesize_spec
    from trustroute.policies.trust_state_synthesis.synthesis import joint_margin

    pomdp, spec = problem("paper", "phi1_trust")
    started = time.perf_counter()
    result = synthesize_spec(pomdp, spec, SynthesisSettings(tau=1e-3, time_limit=TIME_LIMIT, horizon=None))
    value = result.stats.to_dict()["policy_value"]
    rows = [{"name": "unbounded_phi1_trust_synth", "lower": result.lower, "upper": result.upper,
             "seconds": time.perf_counter() - started, "policy_rows": result.stats.policy_rows,
             "junctions_unfolded": value["junctions_unfolded"], "stopped_by": value["stopped_by"],
             "below_peers": PEER_VALUE - result.lower}]
    for nodes in FRONTIERS:
        began = time.perf_counter()
        evaluated = evaluate_joint_table_unbounded(pomdp, spec, result.policy, result.belief_rule, nodes,
                                                   deadline=began + TIME_LIMIT)
        # rounded outward as the synthesis rounds its own L (docs/synthesis.md, "Rounding")
        lower, upper = widen(evaluated.lower, evaluated.upper,
                             joint_margin(pomdp, spec, result.belief_rule, evaluated.junctions))
        rows.append({"name": f"unbounded_phi1_trust_policy_{nodes}_nodes", "lower": lower,
                     "upper": upper, "seconds": time.perf_counter() - began,
                     "junctions_unfolded": evaluated.junctions,
                     "stopped_by": evaluated.stopped_by(),
                     "below_peers": PEER_VALUE - lower})
    return rows
