"""Spec satisfaction of finite traces of positions (road, belief), vectorised over traces.

Position 0 of every trace is its start position; the DFA run starts in `dfa.initial` and
q_t is the state after reading position t. A trace satisfies the spec iff some q_t with
t < length is accepting (a good prefix; docs/model.md, "scLDTL"). Used by `analysis/` on logged
episodes and by the tests as the batch counterpart of the step-by-step DFA.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.networks.town import Town
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec


@dataclass(frozen=True, eq=False)
class TraceResult:
    """satisfied bool [n]; first_accepting int [n] (-1 if never); runs int [n, T]: DFA state after
    reading each position (-1 beyond the trace's length)."""

    satisfied: np.ndarray
    first_accepting: np.ndarray
    runs: np.ndarray


def evaluate_traces(spec: Spec, town: Town, states: np.ndarray, beliefs: np.ndarray,
                    lengths: np.ndarray | None = None, trust: np.ndarray | None = None) -> TraceResult:
    """Evaluate `spec` on n traces: states int [n, T] (indices into town.states), beliefs
    float [n, T, n_trust], lengths int [n] (default T for all), trust int [n, T] (trust level
    index 0..6 at each position; needed iff the spec has trust-state atoms: the true trust in
    simulation, the reported trust on real logs, docs/trust_states.md)."""
    states = np.asarray(states, dtype=np.int64)
    beliefs = np.asarray(beliefs)
    if states.ndim != 2 or beliefs.ndim != 3 or beliefs.shape[:2] != states.shape:
        raise ValueError(f"states {states.shape} and beliefs {beliefs.shape} must be [n, T] and "
                         "[n, T, n_trust]")
    n, horizon = states.shape
    lengths = (np.full(n, horizon, dtype=np.int64) if lengths is None
               else np.asarray(lengths, dtype=np.int64))
    if lengths.shape != (n,) or (lengths < 0).any() or (lengths > horizon).any():
        raise ValueError(f"lengths must be [n] integers in 0..{horizon}")
    if trust is not None:
        trust = np.asarray(trust, dtype=np.int64)
        if trust.shape != states.shape:
            raise ValueError(f"trust {trust.shape} must be [n, T] like states {states.shape}")
    compiled = compile_spec(spec, town)
    dfa, labeller = compiled.dfa, compiled.labeller
    runs = np.full((n, horizon), -1, dtype=np.int64)
    q = np.full(n, dfa.initial, dtype=np.int64)
    # Only traces still running (not yet accepted or rejected, within their length) are stepped:
    # accepting and rejecting states are absorbing, so the rest of their run is known.
    settled = dfa.accepting | dfa.rejecting
    active = np.flatnonzero(lengths > 0)
    for t in range(horizon):
        if active.size:
            q[active] = labeller.step(q[active], states[active, t], beliefs[active, t],
                                      None if trust is None else trust[active, t])
        runs[:, t] = np.where(t < lengths, q, -1)
        active = active[(~settled[q[active]]) & (lengths[active] > t + 1)]
    accepted = (runs >= 0) & dfa.accepting[np.maximum(runs, 0)]
    satisfied = accepted.any(axis=1)
    first = np.where(satisfied, accepted.argmax(axis=1), -1)
    return TraceResult(satisfied=satisfied, first_accepting=first, runs=runs)
