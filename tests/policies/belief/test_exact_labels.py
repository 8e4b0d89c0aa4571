"""Exact belief labels (policies/belief/exact_labels.py): the float filter stays within the bound
of the exact one, labels outside the margin are the exact ones, and labels inside it are decided
on the exact belief of the history's word."""

from __future__ import annotations

import math
import tracemalloc
from fractions import Fraction

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from trustroute.policies.belief.exact_labels import decimal, exact_labels, exact_symbol_matrices, symbol_code
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.labelling import UNIT_ROUNDOFF, atom_values
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.model import trust_pomdp
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
    truth = labels.truth(b0, np.zeros(1, dtype=np.int64))
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
        truth = labels.truth(beliefs, words)
        for row, word in enumerate(words.tolist()):
            exact = labels.filter.belief(word)
            expected = sum(decimal(c) * b for c, b in zip(coeffs, exact, strict=True)) > decimal(offset)
            assert bool(truth[row, 0]) == expected
        if abs(offset - value) > 0.1:
            assert labels.exact_decisions == 0


def test_words_of_one_exact_belief_are_the_same_belief_and_others_are_not():
    """`same_belief` compares the exact beliefs, not the words: on the reset case a standstill and
    a takeover at the obstacle both reset the belief to one row, under two words; the uniform prior
    (the empty word) is another belief."""
    from tests.policies.synthesis.threshold_cases import reset_case

    case = reset_case()
    labels = exact_labels(case.pomdp, compile_spec(case.spec, case.pomdp.town).labeller)
    exact = labels.filter
    obstacle = case.pomdp.driver.incident_types.index("obstacle")
    standstill, takeover = (int(exact.extend(np.zeros(1, dtype=np.int64), symbol_code(obstacle, h, 0))[0])
                            for h in (0, 1))
    assert standstill != takeover and exact.same_belief(standstill, takeover)
    assert not exact.same_belief(0, standstill) and exact.same_belief(0, 0)


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


def _still_population(tmp_path):
    """Two types of weight 0.5 on a town whose roads have no incidents and whose trust never moves:
    type A starts uniform over three levels, type B at the top. The AV's belief stays the prior, so
    P(type B) is exactly 1/2 at every junction."""
    import json

    identity = [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]]
    kinds = ["obstacle", "pedestrian", "truck", "none"]

    def model(**extra):
        return {"trust_levels": [1, 2, 3], "incident_types": kinds,
                "takeover_probability": {k: [0.0] * 3 if k == "none" else [0.5] * 3 for k in kinds},
                "trust_transition": {k: {"takeover": identity, "standstill": identity} for k in kinds},
                **extra}

    town = {"junctions": {"A": [0, 0], "B": [300, 0], "C": [0, 300]},
            "roads": [["A", "B"], ["B", "C"], ["A", "C"]],
            "incidents": {r: "none" for r in ("A-B", "B-A", "B-C", "C-B", "A-C", "C-A")}}
    population = {"format": "trustroute-driver-population", "version": 1, "types": [
        {"name": "A", "weight": 0.5, "model": model()},
        {"name": "B", "weight": 0.5, "model": model(initial_belief=[0.0, 0.0, 1.0])}]}
    (tmp_path / "town.json").write_text(json.dumps(town))
    (tmp_path / "population.json").write_text(json.dumps(population))
    for name, formula in (("tb", "F tb"), ("not_tb", "!tb")):
        (tmp_path / f"{name}.toml").write_text(
            f'name = "{name}"\nstart = "A-B"\nformula = "{formula}"\n'
            '[type_beliefs]\ntb = { types = ["B"], above = 0.5 }\n')
    return tmp_path


def test_a_type_prior_on_a_threshold_is_read_exactly(tmp_path, capsys):
    """The lifted prior λ ⊗ b0 in floats weighs type B a hair over 1/2 (0.5·(1/3) rounds down); the
    exact filter builds it from the weights' and each type's decimals, so `P(B) > 0.5` is false at
    every junction: `F tb` is worth 0 and `!tb` 1, whatever the policy."""
    import json

    from tests.cli import run_cli
    from trustroute.participants.driver_population import load_driver_population
    from trustroute.policies.belief.driver_types import lift_population
    from trustroute.policies.belief.exact_labels import exact_prior

    folder = _still_population(tmp_path)
    lifted = lift_population(load_driver_population(folder / "population.json"))
    prior = exact_prior(lifted)
    assert sum(prior[3:]) == Fraction(1, 2) and sum(prior) == 1
    products = [decimal(b) for b in lifted.initial_belief]       # the float products' decimals
    assert sum(products[3:]) / sum(products) > Fraction(1, 2)
    for name, value in (("tb", 0.0), ("not_tb", 1.0)):
        for objective in ("bayes", "robust"):
            code, out, err = run_cli(
                capsys, "synth", str(folder / f"{name}.toml"), "--town", str(folder / "town.json"),
                "--population", str(folder / "population.json"), "--objective", objective,
                "--horizon", "3", "--out", str(folder / f"{name}-{objective}.json"), "--json")
            assert code == 0, err
            answer = json.loads(out)
            bounds = (answer["lower"], answer["upper"])
            assert bounds[0] <= value <= bounds[1], (name, objective, bounds)


def test_a_compacted_filter_keeps_the_held_words_in_order_and_forgets_the_rest(pomdp, monkeypatch):
    from trustroute.policies.belief import exact_labels as module

    shared = exact_labels(pomdp, compile_spec(_spec(pomdp.town, [0, 0, 0, 1, 1, 1, 1], 0.5),
                                              pomdp.town).labeller)
    with pytest.raises(ValueError, match="shared"):
        shared.filter.compact(np.zeros(1, dtype=np.int64))
    monkeypatch.setattr(module, "COMPACT_AT_LEAST", 0)
    scoped = shared.filter.scoped()
    changing = np.flatnonzero(scoped.changing)
    rng = np.random.default_rng(3)
    words = np.zeros(1, dtype=np.int64)
    for _ in range(5):   # five levels of every changing symbol: a full tree of words
        words = scoped.extend(np.repeat(words, changing.size), np.tile(changing, words.size))
    held = np.sort(rng.choice(words, size=10, replace=False))
    beliefs, lengths, size = [scoped.belief(int(w)) for w in held], scoped.lengths(held), scoped._size
    renumbered = scoped.compact(held)
    assert scoped._size < size / 100 and np.all(np.diff(renumbered) > 0)   # forgotten, order kept
    assert np.array_equal(scoped.lengths(renumbered), lengths)
    assert [scoped.belief(int(w)) for w in renumbered] == beliefs
    extended = scoped.extend(renumbered, np.full(held.size, changing[0]))   # new words, after the held
    assert extended.min() >= scoped._size - held.size and np.array_equal(
        scoped.extend(renumbered, np.full(held.size, changing[0])), extended)   # interned once


def test_a_label_step_in_blocks_of_rows_is_one_step(pomdp, monkeypatch):
    """ExactLabels.step reads BLOCK_ROWS rows at a time: the DFA states, and the labels decided
    exactly, are those of one call, and its temporaries stay a fraction of the beliefs' bytes."""
    town = pomdp.town
    rng = np.random.default_rng(5)

    def rows(n):
        beliefs = rng.dirichlet(np.ones(7), size=n)
        beliefs[::10] = pomdp.initial_belief       # c·b = 2/7 exactly: decided on the exact belief
        return (np.zeros(n, dtype=np.int64), rng.integers(0, len(town.states), size=n), beliefs,
                np.zeros(n, dtype=np.int64))

    def labels():
        return exact_labels(pomdp, compile_spec(_spec(town, [1, 1, 0, 0, 0, 0, 0], 2 / 7), town).labeller)

    small = rows(2_000)
    monkeypatch.setattr(trust_pomdp, "BLOCK_ROWS", 2_000)
    whole = labels()
    one_call = whole.step(*small)
    monkeypatch.setattr(trust_pomdp, "BLOCK_ROWS", 37)
    blocked = labels()
    assert np.array_equal(blocked.step(*small), one_call)
    assert blocked.exact_decisions == whole.exact_decisions == 200
    monkeypatch.undo()
    large = rows(200_000)
    tracemalloc.start()
    try:
        labels().step(*large)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 0.5 * large[2].nbytes, f"{peak / large[2].nbytes:.2f} times the beliefs' bytes"
