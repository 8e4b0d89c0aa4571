"""Beliefs over trust of recorded episodes, from their observations: what the analysis' belief
sources (analysis/belief_sources.py, analysis/satisfaction.py) and the planned studies of
`trustroute plan` (harness/study/planning.py) label each position of a trace with, one definition
for both.

Traces are arrays [n, T] padded beyond each trace's length; position 0 is the start road, where no
observation is read.
"""

from __future__ import annotations

import numpy as np

from trustroute.policies.belief.driver_types import trust_marginal
from trustroute.policies.model.trust_pomdp import TrustPOMDP


def observed_beliefs(pomdp: TrustPOMDP, incident: np.ndarray, takeover: np.ndarray,
                     performance: np.ndarray) -> np.ndarray:
    """float [n, T, n_trust]: the exact Bayes filter of `pomdp`'s driver model, from its initial
    belief, run on the observations int [n, T] (incident index in the model's list, takeover 0/1,
    performance 0 succ / 1 fail), as its trust marginal (a type-aware model's over its types). An
    observation the model gives probability 0 keeps the belief (`TrustPOMDP.filter`)."""
    model = pomdp.driver
    n, horizon = np.shape(incident)
    beliefs = np.zeros((n, horizon, model.n_trust))
    beliefs[:, 0] = model.initial_belief
    for t in range(1, horizon):
        beliefs[:, t] = pomdp.filter(beliefs[:, t - 1], incident[:, t], takeover[:, t], performance[:, t])[0]
    return trust_marginal(model, beliefs)


def reported_beliefs(filter_beliefs: np.ndarray, reports: np.ndarray, levels: tuple[int, ...]) -> np.ndarray:
    """Point mass on the last reported level (carried forward); before any report, the AV's
    initial belief (position 0 of the filter)."""
    n, horizon, k = filter_beliefs.shape
    out = np.repeat(filter_beliefs[:, :1, :], horizon, axis=1)
    lookup = np.full(max(levels) + 2, -1, dtype=np.int64)
    lookup[list(levels)] = np.arange(len(levels))
    last = np.full(n, -1, dtype=np.int64)
    for t in range(horizon):
        reported = reports[:, t] >= 0
        last[reported] = lookup[np.minimum(reports[reported, t], lookup.size - 1)]
        has = np.flatnonzero(last >= 0)
        out[has, t, :] = 0.0
        out[has, t, last[has]] = 1.0
    return out
