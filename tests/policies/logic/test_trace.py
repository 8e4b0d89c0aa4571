"""Batch trace evaluation against the step-by-step DFA and the good-prefix semantics, on town routes."""

from __future__ import annotations

import numpy as np
import pytest

from tests.policies.logic.test_dfa import first_good_prefix
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.logic.trace import evaluate_traces

SHIPPED = ("phi1", "phi2", "phi1_strict", "phi2_strict")


def random_traces(town, start: str, n: int, horizon: int, rng: np.random.Generator):
    """Random legal routes from `start` and random beliefs (Dirichlet, varied concentration)."""
    successors = [[town.state_index(s) for s in town.successors(r)] for r in town.states]
    states = np.empty((n, horizon), dtype=np.int64)
    states[:, 0] = town.state_index(start)
    for t in range(1, horizon):
        for i in range(n):
            options = successors[states[i, t - 1]]
            states[i, t] = options[rng.integers(len(options))]
    # Per-trace trust profiles (flat, high, low) so that both low- and high-trust atoms vary.
    profiles = np.array([[1, 1, 1, 1, 1, 1, 1], [0.1, 0.1, 0.3, 0.5, 1, 2, 2], [2, 2, 1, 0.5, 0.3, 0.2, 0.2]])
    alpha = profiles[rng.integers(3, size=n)][:, None, :] * rng.choice([0.5, 2.0, 8.0], size=(n, horizon, 1))
    beliefs = rng.gamma(alpha)
    beliefs /= beliefs.sum(axis=2, keepdims=True)
    lengths = rng.integers(0, horizon + 1, size=n)
    return states, beliefs, lengths


def direct_valuations(spec, town, dfa, states, beliefs) -> np.ndarray:
    """The labelling written out from the spec's definition (sets and the strict inequality)."""
    n, horizon = states.shape
    values = np.zeros((n, horizon, len(dfa.atoms)), dtype=bool)
    for k, atom in enumerate(dfa.atoms):
        if atom in spec.state_atoms:
            member = np.array([road in spec.state_atoms[atom] for road in town.states])
            values[:, :, k] = member[states]
        else:
            belief = spec.belief_atoms[atom]
            values[:, :, k] = belief.offset - beliefs @ np.array(belief.coeffs) < 0
    return values


@pytest.mark.parametrize("name", SHIPPED)
def test_trace_evaluation_equals_the_step_by_step_dfa_and_the_semantics(town, name):
    spec = load_spec(f"specs/{name}.toml", town)
    dfa = build_dfa(spec)
    rng = np.random.default_rng(8)
    n, horizon = 2000, 30
    states, beliefs, lengths = random_traces(town, spec.start, n, horizon, rng)
    result = evaluate_traces(spec, town, states, beliefs, lengths)
    assert result.runs.shape == (n, horizon)

    labeller = Labeller(spec, dfa, town)
    values = direct_valuations(spec, town, dfa, states, beliefs)
    np.testing.assert_array_equal(labeller.valuations(states.ravel(), beliefs.reshape(-1, 7)),
                                  values.reshape(-1, len(dfa.atoms)))
    for i in range(300):  # the pure-Python DFA step along each trace
        q = dfa.initial
        for t in range(horizon):
            if t >= lengths[i]:
                assert result.runs[i, t] == -1
                continue
            q = dfa.step(q, dict(zip(dfa.atoms, map(bool, values[i, t]), strict=True)))
            assert result.runs[i, t] == q

    # The semantics on every trace truncated to its length.
    det = _first_within(spec, dfa, values, lengths)
    np.testing.assert_array_equal(result.first_accepting, det)
    np.testing.assert_array_equal(result.satisfied, det >= 0)
    assert 0.02 < result.satisfied.mean() < 0.98


def _first_within(spec, dfa, values, lengths):
    first = first_good_prefix(spec.formula, dfa.atoms, values)
    return np.where((first >= 0) & (first < lengths), first, -1)


def test_default_lengths_and_truncation_agree(town):
    spec = load_spec("specs/phi1.toml", town)
    states, beliefs, _ = random_traces(town, spec.start, 500, 25, np.random.default_rng(2))
    full = evaluate_traces(spec, town, states, beliefs)
    short = evaluate_traces(spec, town, states[:, :10], beliefs[:, :10])
    cut = evaluate_traces(spec, town, states, beliefs, np.full(500, 10))
    np.testing.assert_array_equal(cut.runs[:, :10], short.runs)
    assert (cut.runs[:, 10:] == -1).all()
    np.testing.assert_array_equal(cut.first_accepting, short.first_accepting)
    assert (full.satisfied >= short.satisfied).all()


def test_the_paper_route_with_high_trust_at_the_end_satisfies_phi1(town):
    spec = load_spec("specs/phi1.toml", town)
    route = ["E-A", "A-F", "F-G", "G-I", "I-J", "J-K", "K-L"]
    states = np.array([[town.state_index(r) for r in route]])
    low, high = np.full(7, 1 / 7), np.array([0, 0, 0, 0, 0, 0.3, 0.3])
    beliefs = np.tile(low, (1, len(route), 1))
    assert not evaluate_traces(spec, town, states, beliefs, np.array([7])).satisfied[0]
    beliefs[0, -1] = high / high.sum()
    result = evaluate_traces(spec, town, states, beliefs, np.array([7]))
    assert result.satisfied[0] and result.first_accepting[0] == 6


def test_bad_shapes_are_rejected(town):
    spec = load_spec("specs/phi1.toml", town)
    with pytest.raises(ValueError):
        evaluate_traces(spec, town, np.zeros((2, 3), dtype=int), np.zeros((2, 4, 7)), np.array([3, 3]))
    with pytest.raises(ValueError):
        evaluate_traces(spec, town, np.zeros((2, 3), dtype=int), np.zeros((2, 3, 7)), np.array([4, 3]))
