"""The DFA against independent semantics, minimality by brute force, and a 30-atom spec.

Two references that share no code with the progression construction:
- `first_good_prefix`: the informative good-prefix semantics on finite traces, computed backwards
  over positions (dynamic programming on the formula), vectorised over traces. It gives the first
  position t at which the prefix determines satisfaction (docs/model.md, "scLDTL").
- `lasso_satisfies`: LTL satisfaction on ultimately periodic words u v^omega by least fixpoints.
"""

from __future__ import annotations

import itertools
from collections import deque

import numpy as np
import pytest
from hypothesis import given, reject, settings
from hypothesis import strategies as st

from tests.policies.logic.test_formula import formulas
from trustroute.policies.logic.dfa import DFATooLarge, build_dfa, dfa_from_formula, merge_cubes
from trustroute.policies.logic.formula import (
    And,
    Const,
    Eventually,
    Formula,
    Literal,
    Next,
    Or,
    Until,
    canonical,
    disjunctive_normal_form,
    parse_formula,
)
from trustroute.policies.logic.spec import load_spec

SHIPPED = ("phi1", "phi2", "phi1_strict", "phi2_strict")
NEVER = np.iinfo(np.int64).max // 2


# -- independent references -------------------------------------------------------------------

def _determined(formula: Formula, index: dict[str, int], values: np.ndarray) -> np.ndarray:
    """int [n, T+1]: for each trace and position i, the last position the trace must show for
    the formula at i to be informatively true (-1: nothing needed; NEVER: not determined).
    Column T stands for every position after the trace (no letters known there)."""
    n, horizon, _ = values.shape
    positions = np.broadcast_to(np.arange(horizon + 1), (n, horizon + 1))
    if isinstance(formula, Const):
        return np.full((n, horizon + 1), -1 if formula.value else NEVER)
    if isinstance(formula, Literal):
        holds = np.zeros((n, horizon + 1), dtype=bool)
        holds[:, :horizon] = values[:, :, index[formula.atom]] == formula.positive
        return np.where(holds, positions, NEVER)
    if isinstance(formula, And | Or):
        parts = [_determined(p, index, values) for p in formula.parts]
        return np.maximum.reduce(parts) if isinstance(formula, And) else np.minimum.reduce(parts)
    if isinstance(formula, Next):
        body = _determined(formula.body, index, values)
        return np.concatenate([body[:, 1:], body[:, -1:]], axis=1)
    if isinstance(formula, Eventually):
        body = _determined(formula.body, index, values)
        return np.minimum.accumulate(body[:, ::-1], axis=1)[:, ::-1]
    if isinstance(formula, Until):
        left = _determined(formula.left, index, values)
        right = _determined(formula.right, index, values)
        out = right.copy()
        for i in range(horizon - 1, -1, -1):
            out[:, i] = np.minimum(right[:, i], np.maximum(left[:, i], out[:, i + 1]))
        return out
    raise TypeError(formula)


def first_good_prefix(formula: Formula, atoms, values: np.ndarray) -> np.ndarray:
    """int [n]: first position t whose prefix is an (informative) good prefix, -1 if none."""
    det = _determined(formula, {a: i for i, a in enumerate(atoms)}, values)[:, 0]
    first = np.maximum(det, 0)  # the DFA reads position 0 before any check
    return np.where(first < values.shape[1], first, -1)


def lasso_satisfies(formula: Formula, index: dict[str, int], values: np.ndarray, loop: int) -> np.ndarray:
    """bool [n]: whether u v^omega satisfies the formula, values [n, L, k] (v = values[:, loop:])."""
    n, length, _ = values.shape
    nxt = np.append(np.arange(1, length), loop)

    def sat(f: Formula) -> np.ndarray:
        if isinstance(f, Const):
            return np.full((n, length), f.value)
        if isinstance(f, Literal):
            return values[:, :, index[f.atom]] == f.positive
        if isinstance(f, And):
            return np.logical_and.reduce([sat(p) for p in f.parts])
        if isinstance(f, Or):
            return np.logical_or.reduce([sat(p) for p in f.parts])
        if isinstance(f, Next):
            return sat(f.body)[:, nxt]
        left = sat(f.left) if isinstance(f, Until) else np.ones((n, length), dtype=bool)
        right = sat(f.right) if isinstance(f, Until) else sat(f.body)
        out = right.copy()
        for _ in range(length + 1):  # least fixpoint of out = right | (left & out∘next)
            out = right | (left & out[:, nxt])
        return out

    return sat(formula)[:, 0]


def run_dfa(dfa, values: np.ndarray) -> np.ndarray:
    """int [n, T]: the DFA run (state after each position), stepping with step_many."""
    n, horizon, _ = values.shape
    runs = np.empty((n, horizon), dtype=np.int64)
    q = np.full(n, dfa.initial)
    for t in range(horizon):
        q = dfa.step_many(q, values[:, t])
        runs[:, t] = q
    return runs


def first_accepting(dfa, runs: np.ndarray) -> np.ndarray:
    accepted = dfa.accepting[runs]
    return np.where(accepted.any(axis=1), accepted.argmax(axis=1), -1)


# -- shipped specs on random traces -------------------------------------------------------------

@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_spec_dfa_equals_good_prefix_semantics_on_random_traces(town, name):
    spec = load_spec(f"specs/{name}.toml", town)
    dfa = build_dfa(spec)
    rng = np.random.default_rng(1)
    n, horizon = 20_000, 14
    # Per-atom probabilities varied per trace so that both outcomes and every state occur.
    p = rng.uniform(0.05, 0.6, size=(n, 1, len(dfa.atoms)))
    values = rng.random((n, horizon, len(dfa.atoms))) < p
    runs = run_dfa(dfa, values)
    expected = first_good_prefix(spec.formula, dfa.atoms, values)
    np.testing.assert_array_equal(first_accepting(dfa, runs), expected)
    assert 0.1 < (expected >= 0).mean() < 0.9
    assert set(np.unique(runs)) == set(range(dfa.n_states))
    # A rejected run never accepts later (the sink is absorbing) and the semantics agree it fails.
    rejected = dfa.rejecting[runs].any(axis=1)
    assert not (rejected & (expected >= 0)).any()
    assert rejected.any() == bool(dfa.rejecting.any())
    # step_many on one position at a time (its plain walk) agrees with the batch.
    for i in range(200):
        q = np.array([dfa.initial])
        for t in range(horizon):
            q = dfa.step_many(q, values[i:i + 1, t])
            assert q.shape == (1,) and q.dtype == runs.dtype and q[0] == runs[i, t]
    # The scalar step agrees with step_many on a sample.
    for i in range(200):
        q = dfa.initial
        for t in range(horizon):
            q = dfa.step(q, dict(zip(dfa.atoms, map(bool, values[i, t]), strict=True)))
            assert q == runs[i, t]


def test_shipped_dfa_sizes(town):
    sizes = {name: build_dfa(load_spec(f"specs/{name}.toml", town)).n_states for name in SHIPPED}
    # phi: waiting for v1, v2, v3&hightrust, accepted; strict adds the sink for low trust before v1.
    assert sizes == {"phi1": 4, "phi2": 4, "phi1_strict": 5, "phi2_strict": 5}


# -- minimality by brute force ----------------------------------------------------------------

def explicit_table(dfa) -> np.ndarray:
    letters = list(itertools.product([False, True], repeat=len(dfa.atoms)))
    return np.array([[dfa.step(q, dict(zip(dfa.atoms, letter, strict=True))) for letter in letters]
                     for q in range(dfa.n_states)])


def assert_minimal_and_complete(dfa) -> None:
    table = explicit_table(dfa)  # complete: step answers every state and letter
    assert table.min() >= 0 and table.max() < dfa.n_states
    reached = {dfa.initial}
    queue = deque([dfa.initial])
    while queue:
        for t in table[queue.popleft()]:
            if int(t) not in reached:
                reached.add(int(t))
                queue.append(int(t))
    assert reached == set(range(dfa.n_states)), "every state is reachable"
    for q in np.flatnonzero(dfa.accepting):
        assert (table[q] == q).all(), "accepting states are absorbing"
    for p, q in itertools.combinations(range(dfa.n_states), 2):
        # Breadth-first search over pairs for a word that one state accepts and the other not.
        seen = {(p, q)}
        queue = deque([(p, q)])
        found = False
        while queue and not found:
            s, t = queue.popleft()
            if dfa.accepting[s] != dfa.accepting[t]:
                found = True
                break
            for nxt in zip(table[s], table[t], strict=True):
                pair = (int(nxt[0]), int(nxt[1]))
                if pair not in seen:
                    seen.add(pair)
                    queue.append(pair)
        assert found, f"states {p} and {q} are equivalent: the DFA is not minimal"
    # rejecting = acceptance unreachable
    for q in range(dfa.n_states):
        can = {q}
        queue = deque([q])
        while queue:
            for t in table[queue.popleft()]:
                if int(t) not in can:
                    can.add(int(t))
                    queue.append(int(t))
        assert dfa.rejecting[q] == (not any(dfa.accepting[s] for s in can))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_dfas_are_minimal(town, name):
    assert_minimal_and_complete(build_dfa(load_spec(f"specs/{name}.toml", town)))


@pytest.mark.parametrize("text", [
    "a U (F b)", "F a & F b", "(a U b) | (c U b)", "X X a | F (b & X c)", "!a U (b & X (!c U a))",
    "F (a & X false)", "X a | X !a", "(a | b) U (c & X (a | !a))",
])
def test_small_formula_dfas_are_minimal(text):
    assert_minimal_and_complete(dfa_from_formula(parse_formula(text)))


# -- random formulas on lassos ---------------------------------------------------------------------

@settings(max_examples=200, deadline=None)
@given(st.one_of(formulas(max_leaves=6), formulas(max_leaves=14, constants=False)), st.integers(0, 2**32 - 1))
def test_random_formula_dfa_agrees_with_lasso_semantics(formula, seed):
    atoms = ("a", "b", "c", "v1", "hightrust")
    try:
        dfa = dfa_from_formula(formula, atoms, max_states=2000)
    except DFATooLarge:
        reject()  # LTL to DFA is doubly exponential in the worst case; not what this test is about
    index = {a: i for i, a in enumerate(atoms)}
    rng = np.random.default_rng(seed)
    for prefix, period in ((0, 1), (1, 2), (2, 3), (3, 1), (0, 4)):
        values = rng.random((40, prefix + period, len(atoms))) < 0.5
        expected = lasso_satisfies(formula, index, values, prefix)
        q = np.full(len(values), dfa.initial)
        for t in range(prefix):
            q = dfa.step_many(q, values[:, t])
        for _ in range(dfa.n_states + 1):  # enough laps for the run to settle on v^omega
            for t in range(prefix, prefix + period):
                q = dfa.step_many(q, values[:, t])
        np.testing.assert_array_equal(dfa.accepting[q], expected)
        # Accepting means every continuation satisfies: so does the lasso; rejecting: none does.
        assert not (dfa.rejecting[q] & expected).any()


@settings(max_examples=100, deadline=None)
@given(formulas(max_leaves=12, constants=False))
def test_random_formula_dfas_are_minimal(formula):
    try:
        dfa = dfa_from_formula(formula, max_states=500)
    except DFATooLarge:
        reject()
    assert_minimal_and_complete(dfa)


@pytest.mark.parametrize(("stages", "guarded"), [(3, 2), (2, 2), (4, 1)])
def test_guarded_chain_dfas_are_minimal(stages, guarded):
    assert_minimal_and_complete(dfa_from_formula(parse_formula(guarded_chain(stages, guarded))))


@settings(max_examples=200, deadline=None)
@given(formulas(max_leaves=12), st.integers(0, 2**32 - 1))
def test_canonical_form_and_dnf_keep_the_meaning(formula, seed):
    atoms = ("a", "b", "c", "v1", "hightrust")
    index = {a: i for i, a in enumerate(atoms)}
    rng = np.random.default_rng(seed)
    values = rng.random((60, 4, len(atoms))) < 0.5
    expected = lasso_satisfies(formula, index, values, 1)
    np.testing.assert_array_equal(lasso_satisfies(canonical(formula), index, values, 1), expected)
    np.testing.assert_array_equal(lasso_satisfies(disjunctive_normal_form(formula), index, values, 1),
                                  expected)


@pytest.mark.parametrize("text", ["F a U F b", "(X a U v1) U F !a", "(F a U F b) U (F c U X a)"])
def test_progression_terminates_on_nested_temporal_operators(text):
    # Without a normal form for states, progression of F a U F b nests And/Or forever.
    dfa = dfa_from_formula(parse_formula(text))
    assert dfa.n_states <= 8
    assert_minimal_and_complete(dfa)


def test_too_large_formula_is_an_input_error(monkeypatch):
    from trustroute.core.errors import InputError
    from trustroute.policies.logic.spec import spec_from_text

    text = " & ".join(f"F a{i}" for i in range(8))
    with pytest.raises(DFATooLarge):
        dfa_from_formula(parse_formula(text), max_states=100)
    assert dfa_from_formula(parse_formula(text)).n_states == 2**8
    states = "\n".join(f'a{i} = ["A-B"]' for i in range(8))
    spec = spec_from_text(f'name = "big"\nstart = "A-B"\nformula = "{text}"\n[states]\n{states}\n')
    monkeypatch.setattr("trustroute.policies.logic.dfa.MAX_STATES", 100)
    with pytest.raises(InputError, match="too large to translate"):
        build_dfa(spec)


def test_acceptance_is_at_the_first_good_prefix_even_when_not_informative():
    dfa = dfa_from_formula(parse_formula("X a | X !a"))
    assert dfa.accepting[dfa.initial]  # every trace satisfies it: accepted before reading anything
    dfa = dfa_from_formula(parse_formula("F (a & X false)"))
    assert dfa.n_states == 1 and dfa.rejecting[dfa.initial]
    dfa = dfa_from_formula(parse_formula("b & X (a | !a)"))
    assert dfa.accepting[dfa.step(dfa.initial, {"b": True})]


@pytest.mark.parametrize("text", ["(a | b) U (c & X a)", "F (a & X (b | c)) | F c", "!a U (b & c) | X X a"])
def test_merged_guards_are_equivalent_to_the_diagrams(text):
    dfa = dfa_from_formula(parse_formula(text))
    for q in range(dfa.n_states):
        guards = {t: merge_cubes(cubes, dfa.atoms) for t, cubes in dfa.transitions(q).items()}
        for letter in itertools.product([False, True], repeat=len(dfa.atoms)):
            valuation = dict(zip(dfa.atoms, letter, strict=True))
            hit = [t for t, cubes in guards.items()
                   if any(all(valuation[a] == v for a, v in cube) for cube in cubes)]
            assert hit == [dfa.step(q, valuation)]


def test_step_many_on_empty_input_and_guards():
    dfa = dfa_from_formula(parse_formula("!a U b"))
    assert dfa.step_many(np.array([], dtype=np.int64), np.zeros((0, 2), dtype=bool)).shape == (0,)
    guards = dfa.transitions(dfa.initial)
    covered = sum(2 ** (len(dfa.atoms) - len(cube)) for cubes in guards.values() for cube in cubes)
    assert covered == 2 ** len(dfa.atoms)  # the guards partition the letters
    dot = dfa.to_dot()
    assert dot.startswith('digraph "dfa"') and "doublecircle" in dot and "->" in dot


# -- 30 atoms -----------------------------------------------------------------------------------

def guarded_chain(stages: int, guarded: int) -> str:
    """Waypoints w_i with belief conditions b_i in order; the first `guarded` stages must keep
    !c_i until their waypoint (each c_i a separate atom): 2*stages + guarded atoms."""
    text = "true"
    for i in range(stages, 0, -1):
        inner = f"w{i} & b{i}" + ("" if text == "true" else f" & ({text})")
        text = f"!c{i} U ({inner})" if i <= guarded else f"F ({inner})"
    return text


@pytest.mark.parametrize(("stages", "guarded", "states"), [(15, 0, 16), (12, 6, None)])
def test_thirty_atom_specs_translate_and_agree_with_the_semantics(stages, guarded, states):
    formula = parse_formula(guarded_chain(stages, guarded))
    dfa = dfa_from_formula(formula)
    assert len(dfa.atoms) == 30
    if states is not None:  # a chain of F stages: one state per stage reached, plus acceptance
        assert dfa.n_states == states
    rng = np.random.default_rng(5)
    n, horizon = 10_000, 40
    kinds = np.array([a[0] for a in dfa.atoms])
    p = np.where(kinds == "c", 0.03, 0.6)  # rare guard violations, frequent waypoints
    values = rng.random((n, horizon, len(dfa.atoms))) < p
    expected = first_good_prefix(formula, dfa.atoms, values)
    np.testing.assert_array_equal(first_accepting(dfa, run_dfa(dfa, values)), expected)
    assert 0.05 < (expected >= 0).mean() < 0.95
