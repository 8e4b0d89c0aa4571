"""scLDTL: DFA translation time (shipped specs and 30-atom specs) and batch trace evaluation.

- Translation (formula -> complete minimal DFA) of the four shipped specs and of 30-atom specs:
  a 15-waypoint sequence (each waypoint with a belief condition), a 12-stage sequence whose first
  6 stages are guarded by `!c_i U ...`, and a fully guarded 10-stage sequence whose minimal DFA is
  genuinely exponential (2^10 + 1 states; every subset of live stages must be remembered).
- Trace evaluation: `evaluate_traces` on 10^5 random legal routes of length 30 with random beliefs
  for phi1_strict; baseline measured in the same run: the pure-Python loop a caller would otherwise
  write (labelling dict per position + `DFA.step`), timed on a subset and scaled linearly to 10^5.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.timing import best_seconds
from trustroute.networks.town import load_town
from trustroute.policies.logic.dfa import build_dfa, dfa_from_formula
from trustroute.policies.logic.formula import parse_formula
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.logic.trace import evaluate_traces

SHIPPED = ("phi1", "phi2", "phi1_strict", "phi2_strict")
N_TRACES = 100_000
HORIZON = 30
BASELINE_TRACES = 2_000


def guarded_chain(stages: int, guarded: int) -> str:
    """Waypoints w_i & b_i in order; the first `guarded` stages need !c_i until their waypoint."""
    text = "true"
    for i in range(stages, 0, -1):
        inner = f"w{i} & b{i}" + ("" if text == "true" else f" & ({text})")
        text = f"!c{i} U ({inner})" if i <= guarded else f"F ({inner})"
    return text


def random_traces(town, start: str, n: int, horizon: int, rng: np.random.Generator):
    """Random legal routes (uniform next junction) and Dirichlet beliefs, vectorised."""
    successors = [[town.state_index(s) for s in town.successors(r)] for r in town.states]
    width = max(len(s) for s in successors)
    table = np.array([s + [s[0]] * (width - len(s)) for s in successors])
    counts = np.array([len(s) for s in successors])
    states = np.empty((n, horizon), dtype=np.int64)
    states[:, 0] = town.state_index(start)
    for t in range(1, horizon):
        previous = states[:, t - 1]
        states[:, t] = table[previous, (rng.random(n) * counts[previous]).astype(np.int64)]
    beliefs = rng.gamma(np.array([0.5, 0.5, 1, 1, 1, 2, 2]), size=(n, horizon, 7))
    beliefs /= beliefs.sum(axis=2, keepdims=True)
    return states, beliefs


def python_loop(spec, town, dfa, states, beliefs) -> np.ndarray:
    """Baseline: label each position in Python and step the DFA one position at a time."""
    state_sets = {a: spec.state_atoms[a] for a in dfa.atoms if a in spec.state_atoms}
    belief_atoms = {a: spec.belief_atoms[a] for a in dfa.atoms if a in spec.belief_atoms}
    roads = town.states
    satisfied = np.zeros(len(states), dtype=bool)
    for i in range(len(states)):
        q = dfa.initial
        for t in range(states.shape[1]):
            road, belief = roads[states[i, t]], beliefs[i, t]
            valuation = {a: road in s for a, s in state_sets.items()}
            for a, atom in belief_atoms.items():
                valuation[a] = atom.offset - float(np.dot(atom.coeffs, belief)) < 0
            q = dfa.step(q, valuation)
            if dfa.accepting[q]:
                satisfied[i] = True
                break
            if dfa.rejecting[q]:
                break
    return satisfied


def run() -> list[dict]:
    town = load_town()
    results: list[dict] = []
    for name in SHIPPED:
        spec = load_spec(f"specs/{name}.toml", town)
        dfa = dfa_from_formula(spec.formula, spec.formula_atoms)
        seconds = best_seconds(lambda spec=spec: dfa_from_formula(spec.formula, spec.formula_atoms))
        results.append({"name": f"spec.translate.{name}", "value": seconds, "unit": "s",
                        "dfa_states": dfa.n_states, "atoms": len(dfa.atoms)})
    for label, stages, guarded in (("30atoms.sequence", 15, 0), ("30atoms.guarded6", 12, 6),
                                   ("30atoms.guarded10_exponential", 10, 10)):
        formula = parse_formula(guarded_chain(stages, guarded))
        dfa = dfa_from_formula(formula)
        repeats = 1 if dfa.n_states > 200 else 3
        seconds = best_seconds(lambda formula=formula: dfa_from_formula(formula), repeats=repeats)
        results.append({"name": f"spec.translate.{label}", "value": seconds, "unit": "s",
                        "dfa_states": dfa.n_states, "atoms": len(dfa.atoms),
                        "guard_nodes": int(len(dfa.node_atom))})

    spec = load_spec("specs/phi1_strict.toml", town)
    rng = np.random.default_rng(0)
    states, beliefs = random_traces(town, spec.start, N_TRACES, HORIZON, rng)
    lengths = np.full(N_TRACES, HORIZON)
    result = evaluate_traces(spec, town, states, beliefs, lengths)
    seconds = best_seconds(lambda: evaluate_traces(spec, town, states, beliefs, lengths), repeats=3)
    dfa = build_dfa(spec)
    started = time.perf_counter()
    slow = python_loop(spec, town, dfa, states[:BASELINE_TRACES], beliefs[:BASELINE_TRACES])
    baseline = (time.perf_counter() - started) * N_TRACES / BASELINE_TRACES
    assert (slow == result.satisfied[:BASELINE_TRACES]).all(), "baseline and evaluator disagree"
    results.append({"name": "spec.evaluate_traces.phi1_strict.1e5x30", "value": seconds, "unit": "s",
                    "baseline": baseline, "ratio": baseline / seconds,
                    "baseline_what": f"pure-Python labelling + DFA.step loop (stops at acceptance or "
                                     f"rejection), timed on {BASELINE_TRACES} traces, scaled to "
                                     f"{N_TRACES}",
                    "traces": N_TRACES, "length": HORIZON, "dfa_states": dfa.n_states,
                    "satisfied_fraction": float(result.satisfied.mean())})
    return results
