"""Our upper bound against Storm's on the paper's town with the trust atom at H = 20
(docs/peers.md): the synthesis at the peer table's τ = 1e-3 and at τ = 1e-6 (so the rounds go on
until the time limit), 60 s each, with every round's nodes per level, search upper bound and cut
nodes. Storm's discretisation gives 0.99707 there (the peer table's run); `above_storm_upper` is
negative where ours is the tighter.
"""

from __future__ import annotations

import time

STORM_UPPER = 0.99707          # docs/peers.md, the peer table's run
TIME_LIMIT = 60.0
TAUS = (1e-3, 1e-6)


def run() -> list[dict]:
    from benchmarks.bench_peers import problem
    from trustroute.policies.synthesis.settings import SynthesisSettings
    from trustroute.policies.synthesize_spec import synthesize_spec

    pomdp, spec = problem("paper", "phi1_trust")
    rows = []
    for tau in TAUS:
        started = time.perf_counter()
        result = synthesize_spec(pomdp, spec, SynthesisSettings(tau=tau, time_limit=TIME_LIMIT, horizon=20))
        rows.append({"name": f"paper_phi1_trust_h20_tau_{tau:g}", "lower": result.lower,
                     "upper": result.upper, "seconds": time.perf_counter() - started,
                     "above_storm_upper": result.upper - STORM_UPPER,
                     "rounds": [{"max_nodes": run.max_nodes, "upper": run.bounds.upper,
                                 "cut_nodes": run.bounds.cut_nodes, "seconds": run.bounds.seconds}
                                for run in result.stats.runs]})
    return rows
