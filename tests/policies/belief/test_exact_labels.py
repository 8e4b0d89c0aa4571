"""Exact belief labels (policies/belief/exact_labels.py): the float filter stays within the bound
of the exact one, labels outside the margin are the exact ones, and labels inside it are decided
on the exact belief of the history's word."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from trustroute.policies.belief.exact_labels import decimal, exact_labels, exact_symbol_matrices, symbol_code
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.labelling import UNIT_ROUNDOFF, atom_values
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.model.trust_pomdp import build_pomdp


def _spec(town, coeffs, offset: float):
    text = (f'name = "t"\nstart = "{town.states[0]}"\nformula = "F high"\n'
            f"[beliefs.high]\ncoeffs = {list(map(float, coeffs))}\noffset = {offset!r}\n")
    return spec_from_text(text, "<exact labels spec>", town)


def _hilbert(float_belief: np.ndarray, exact: tuple[Fraction, ...]) -> float:
    ratios = [Fraction(float(f)) / e for f, e in zip(float_belief, exact, strict=True) if e]
    assert all(f == 0 for f, e in zip(float_belief, exact, strict=True) if not e)   # one support
    return math.log(max(ratios) / min(ratios))


def _random_walk(pomdp, labels, rng, steps: int):
    """Float beliefs and words along `steps` random observations of positive probability."""
    belief = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    word = np.zeros(1, dtype=np.int64)
    n_inc = len(pomdp.driver.incident_types)
    out = [(belief[0], int(word[0]))]
    while len(out) <= steps:
        i, h, e = int(rng.integers(n_inc)), int(rng.integers(2)), int(rng.integers(2))
        posterior, probability = pomdp.belief_update(belief, i, h, e)
        if probability[0] <= 0:
            continue
        belief, word = posterior, labels.filter.extend(word, symbol_code(i, h, e))
        out.append((belief[0], int(word[0])))
    return out


@pytest.mark.parametrize("seed", range(4))
def test_the_float_filter_stays_within_the_bound_of_the_exact_one(town, driver, seed):
    rng = np.random.default_rng(seed)
    model = driver if seed == 0 else random_driver(rng, driver.incident_types)
    pomdp = build_pomdp(town, model)
    labels = exact_labels(pomdp, compile_spec(_spec(town, [1, 1, 0, 0, 0, 0, 0], 0.3), town).labeller)
    for belief, word in _random_walk(pomdp, labels, rng, 30):
        exact = labels.filter.belief(word)
        assert sum(exact) == 1
        assert _hilbert(belief, exact) <= labels.filter.distance(np.array([word]))[0]


def test_the_uniform_prior_is_exactly_one_seventh_per_level(town, driver):
    pomdp = build_pomdp(town, driver)
    labels = exact_labels(pomdp, compile_spec(_spec(town, [1, 1, 0, 0, 0, 0, 0], 2 / 7), town).labeller)
    assert labels.filter.prior == (Fraction(1, 7),) * 7
    assert decimal(2 / 7) == Fraction("0.2857142857142857") < Fraction(2, 7)


@pytest.mark.parametrize("k", range(1, 7))
@pytest.mark.parametrize("nudge", [-1, 0, 1])
def test_k_sevenths_at_the_uniform_prior_are_decided_exactly(town, driver, k, nudge):
    """c·b = k/7 exactly; the float c·b̂ equals float(k/7) or is an ulp off: the float label is
    undecided and the exact one is read (offset = the decimal written in the spec)."""
    pomdp = build_pomdp(town, driver)
    offset = k / 7 if not nudge else float(np.nextafter(k / 7, np.inf * nudge))
    coeffs = [1.0] * k + [0.0] * (7 - k)
    labels = exact_labels(pomdp, compile_spec(_spec(town, coeffs, offset), town).labeller)
    b0 = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    truth, either = labels.truth(b0, np.zeros(1, dtype=np.int64))
    assert not either.any()
    assert bool(truth[0, 0]) == (Fraction(k, 7) > decimal(offset))
    assert labels.exact_decisions == 1


@pytest.mark.parametrize("seed", range(6))
def test_labels_equal_the_exact_filter_s_at_and_next_to_reached_values(town, driver, seed):
    """Offsets at c·b̂ of a reached belief, one ulp either side, and far away: `truth` is the
    exact label every time, and the far offsets are decided in floats."""
    rng = np.random.default_rng(100 + seed)
    pomdp = build_pomdp(town, driver if seed % 2 else random_driver(rng, driver.incident_types))
    coeffs = np.zeros(7)
    coeffs[rng.choice(7, size=int(rng.integers(1, 7)), replace=False)] = 1.0
    plain = exact_labels(pomdp, compile_spec(_spec(town, coeffs, 0.5), town).labeller)
    walk = _random_walk(pomdp, plain, rng, 12)
    target_belief, _ = walk[int(rng.integers(len(walk)))]
    value = float(atom_values(target_belief[None, :], coeffs[:, None])[0, 0])
    for offset in (value, float(np.nextafter(value, 1.0)), float(np.nextafter(value, 0.0)),
                   value + 0.25, value - 0.25):
        labels = exact_labels(pomdp, compile_spec(_spec(town, coeffs, offset), town).labeller)
        walk = _random_walk(pomdp, labels, np.random.default_rng(seed), 12)
        beliefs = np.array([b for b, _ in walk])
        words = np.array([w for _, w in walk])
        truth, either = labels.truth(beliefs, words)
        assert not either.any()
        for row, word in enumerate(words.tolist()):
            exact = labels.filter.belief(word)
            expected = sum(decimal(c) * b for c, b in zip(coeffs, exact, strict=True)) > decimal(offset)
            assert bool(truth[row, 0]) == expected
        if abs(offset - value) > 0.1:
            assert labels.exact_decisions == 0


def test_a_node_of_several_words_branches_where_floats_cannot_decide(town, driver):
    pomdp = build_pomdp(town, driver)
    labels = exact_labels(pomdp, compile_spec(_spec(town, [1, 1, 0, 0, 0, 0, 0], 2 / 7), town).labeller)
    b0 = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    truth, either = labels.truth(b0, np.zeros(1, dtype=np.int64), undecidable=np.array([True]))
    assert either.all() and labels.exact_decisions == 0


def test_rows_merge_only_within_one_word_and_keep_distinct_rows_grouping_otherwise():
    from trustroute.policies.belief.trust_state_filter import distinct_rows, split_by_words

    rows = np.array([[0.5, 0.5], [0.25, 0.75], [0.5, 0.5], [0.25, 0.75], [0.5, 0.5]])
    first, inverse = distinct_rows(rows)
    same = split_by_words(first, inverse, np.array([3, 1, 3, 1, 3]))
    assert np.array_equal(same[0], first) and np.array_equal(same[1], inverse)
    split_first, split_inverse = split_by_words(first, inverse, np.array([3, 1, 4, 1, 3]))
    assert np.array_equal(split_first[:first.size], first)          # the groups before, in order
    assert split_inverse[0] == split_inverse[4] != split_inverse[2]
    assert split_inverse[1] == split_inverse[3] == inverse[1]
    assert split_first[split_inverse[2]] == 2


def test_the_conversion_s_numbers_equal_those_computed_entry_by_entry_in_fractions(town):
    """The symbol matrices and their float gap, computed with each decimal once and the gap in
    integers, equal the direct computation: every entry weight·decimal(T) as a Fraction, and the
    gap as |Fraction(float) - exact| / |exact| in Fractions, rounded up the same way."""
    rng = np.random.default_rng(5)
    pomdp = build_pomdp(town, random_driver(rng, ("none", "pedestrian", "obstacle", "truck")))
    driver, n = pomdp.driver, pomdp.n_trust
    for rule in ("bayes", "paper"):
        matrices, _, worst = exact_symbol_matrices(pomdp, rule)
        floats = pomdp.weighted_transition if rule == "bayes" else driver.trust_transition
        expected_worst = 0.0
        for i in range(len(driver.incident_types)):
            for h in (0, 1):
                for e in (0, 1):
                    t = [decimal(v) for v in driver.takeover_probability[i]]
                    f = [decimal(v) for v in driver.failure_probability[i]]
                    like = [(t[k] if h else 1 - t[k]) * (f[k] if e else 1 - f[k]) for k in range(n)]
                    weights = like if rule == "bayes" else [Fraction(1)] * n
                    matrix = matrices[int(symbol_code(i, h, e))]
                    for k in range(n):
                        for m in range(n):
                            exact = weights[k] * decimal(driver.trust_transition[i, h, e, k, m])
                            assert matrix[k][m] == exact
                            if any(like) and exact != 0:
                                gap = abs(Fraction(float(floats[i, h, e, k, m])) - exact) / abs(exact)
                                expected_worst = max(expected_worst, float(gap) * (1 + 4 * UNIT_ROUNDOFF))
        assert worst == expected_worst
