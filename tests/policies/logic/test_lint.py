"""The spec linter: exact warnings for the shipped specs, and each check against an independent method."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from trustroute.networks.town import town_from_dict
from trustroute.policies.logic.lint import belief_warnings, lint, town_satisfiable
from trustroute.policies.logic.spec import load_spec, spec_from_text


def codes(warnings):
    return sorted((w.code, w.atom) for w in warnings)


@pytest.mark.parametrize("name", ["phi1", "phi2"])
def test_paper_specs_get_exactly_the_two_warnings_that_apply(town, name):
    warnings = lint(load_spec(f"specs/{name}.toml", town), town)
    assert codes(warnings) == [("atom-no-effect", "lowtrust"), ("belief-never-true", "lowtrust")]
    never = next(w for w in warnings if w.code == "belief-never-true")
    assert "never true on the probability simplex" in never.message


@pytest.mark.parametrize("name", ["phi1_strict", "phi2_strict"])
def test_strict_specs_get_no_warnings(town, name):
    assert lint(load_spec(f"specs/{name}.toml", town), town) == []


def spec_text(formula: str, states: dict | None = None, beliefs: dict | None = None,
              start: str = "E-A") -> str:
    lines = ['name = "t"', f'start = "{start}"', f'formula = "{formula}"', "[states]"]
    lines += [f"{k} = {list(v)!r}".replace("'", '"') for k, v in (states or {}).items()]
    for k, (coeffs, offset) in (beliefs or {}).items():
        lines += [f"[beliefs.{k}]", f"coeffs = {list(coeffs)!r}", f"offset = {offset!r}"]
    return "\n".join(lines) + "\n"


def max_on_simplex(c: np.ndarray) -> float:
    """max c.b over the simplex by linear programming (independent of the vertex argument)."""
    result = linprog(-c, A_eq=np.ones((1, len(c))), b_eq=[1.0], bounds=[(0, None)] * len(c))
    return -result.fun


def test_belief_checks_agree_with_linear_programming():
    rng = np.random.default_rng(3)
    seen = set()
    for _ in range(300):
        coeffs = np.round(rng.normal(size=7), 1) * rng.integers(0, 2, size=7)
        offset = float(np.round(rng.normal() * 0.8, 1))
        spec = spec_from_text(spec_text("p", beliefs={"p": (coeffs.tolist(), offset)}))
        found = {w.code for w in belief_warnings(spec)}
        never = max_on_simplex(coeffs) <= offset + 1e-9       # never offset - c.b < 0
        always = -max_on_simplex(-coeffs) > offset + 1e-9     # min c.b > offset
        assert ("belief-never-true" in found) == never
        assert ("belief-always-true" in found) == always
        seen.add((never, always))
    assert seen == {(True, False), (False, True), (False, False)}


@pytest.mark.parametrize(("formula", "no_effect"), [
    ("a U (F b)", ["a"]),
    ("a U b", []),
    ("F b & (c | !c)", ["c"]),        # a tautology: the canonical form drops it before translation
    ("F (b & (c | X c | X !c))", ["c"]),
    ("(a & b) U b", ["a"]),           # when b holds the U is done; when not, a & b fails anyway
    ("(a | b) U b", []),
    ("X (a U b) | F b", ["a"]),
    ("F (a & b) | F b", ["a"]),
])
def test_atom_without_effect_is_found_from_the_dfa(formula, no_effect):
    spec = spec_from_text(spec_text(formula, states={"a": ["A-B"], "b": ["B-C"], "c": ["C-D"]}))
    warnings = [w for w in lint(spec) if w.code == "atom-no-effect"]
    assert sorted(w.atom for w in warnings) == no_effect


def test_atom_without_effect_agrees_with_brute_force_on_the_dfa():
    # Brute force: an atom matters iff flipping it changes the successor of some state on some letter.
    from trustroute.policies.logic.dfa import build_dfa
    for formula in ["a U (F b)", "(a | b) U (c & X a)", "F (a & X (b | c)) | F c", "(a U b) & F (c | a)"]:
        spec = spec_from_text(spec_text(formula, states={"a": ["A-B"], "b": ["B-C"], "c": ["C-D"]}))
        dfa = build_dfa(spec)
        matters = set()
        for q in range(dfa.n_states):
            for letter in itertools.product([False, True], repeat=len(dfa.atoms)):
                valuation = dict(zip(dfa.atoms, letter, strict=True))
                for atom in dfa.atoms:
                    if dfa.step(q, valuation) != dfa.step(q, {**valuation, atom: not valuation[atom]}):
                        matters.add(atom)
        flagged = {w.atom for w in lint(spec) if w.code == "atom-no-effect"}
        assert flagged == set(dfa.atoms) - matters


@pytest.mark.parametrize(("formula", "expected"), [
    ("(b & c) U F b", [("atom-no-effect", "c"), ("subformula-no-effect", "b & c")]),
    ("X ((a | b) U F b) & F c", [("atom-no-effect", "a"), ("subformula-no-effect", "a | b")]),
    ("(a & c) U F b", [("atom-no-effect", "a"), ("atom-no-effect", "c")]),  # not repeated
    # F b & F (b | c) = F b, so c is irrelevant; but F (b | c) is not: replaced by false, the spec fails
    ("F b & F (b | c)", [("atom-no-effect", "c")]),
    ("(a & F b) | F b", [("atom-no-effect", "a")]),
])
def test_subformula_without_effect(formula, expected):
    spec = spec_from_text(spec_text(formula, states={"a": ["A-B"], "b": ["B-C"], "c": ["C-D"]}))
    found = []
    for w in lint(spec):
        if w.code == "unused-atom":
            continue
        if w.code == "subformula-no-effect":
            found.append((w.code, w.message.split("'")[1]))
        else:
            found.append((w.code, w.atom))
    assert sorted(found) == expected


def test_dfa_equivalence_against_brute_force():
    from trustroute.policies.logic.dfa import dfa_from_formula
    from trustroute.policies.logic.formula import parse_formula
    from trustroute.policies.logic.lint import equivalent
    pairs = [("a U F b", "F b", True), ("a U b", "b", False), ("F (a | b)", "F a | F b", True),
             ("X a & X b", "X (a & b)", True), ("F (a & X b)", "F a & F b", False),
             ("(a | b) U c", "(b | a) U (c | c & a)", True), ("X a", "X X a", False)]
    for left, right, same in pairs:
        assert equivalent(dfa_from_formula(parse_formula(left), ("a", "b", "c")),
                          dfa_from_formula(parse_formula(right), ("a", "b", "c"))) == same


def test_unused_atom_and_unsatisfiable_formula():
    spec = spec_from_text(spec_text("F a", states={"a": ["A-B"], "b": ["B-C"]}))
    assert codes(lint(spec)) == [("unused-atom", "b")]
    spec = spec_from_text(spec_text("F (a & X false)", states={"a": ["A-B"]}))
    assert ("unsatisfiable", "") in codes(lint(spec))


TRIANGLE = {
    # One-way in effect: from B-C the vehicle never turns back, so it circles B -> C -> D -> B.
    "junctions": {"B": [0, 0], "C": [100, 0], "D": [50, 80]},
    "roads": [["B", "C"], ["C", "D"], ["D", "B"]],
    "incidents": {r: "none" for r in ["B-C", "C-B", "C-D", "D-C", "D-B", "B-D"]},
}


def test_state_atom_unreachable_and_town_unsatisfiable():
    town = town_from_dict(TRIANGLE, "triangle")
    assert town.reachable_states("B-C") == {"B-C", "C-D", "D-B"}
    spec = spec_from_text(spec_text("F a & F b", states={"a": ["C-B", "D-C"], "b": ["C-D"]}, start="B-C"),
                          town=town)
    assert codes(lint(spec, town)) == [("state-unreachable", "a"), ("town-unsatisfiable", "")]
    # Reachable atoms, but never in this order: C-D is always followed by D-B, not B-C.
    text = spec_text("F (a & X b)", states={"a": ["C-D"], "b": ["B-C"]}, start="B-C")
    spec = spec_from_text(text, town=town)
    assert codes(lint(spec, town)) == [("town-unsatisfiable", "")]
    spec = spec_from_text(text.replace('b = ["B-C"]', 'b = ["D-B"]'), town=town)
    assert lint(spec, town) == []


def test_town_satisfiability_ignores_belief_atoms(town):
    # The strict spec needs hightrust at v3 and no lowtrust before v1: still satisfiable by some route.
    assert town_satisfiable(load_spec("specs/phi1_strict.toml", town), town)
    text = Path("specs/phi1_strict.toml").read_text().replace('v3 = ["K-L", "E-L", "H-L"]', 'v3 = ["E-A"]')
    assert town_satisfiable(spec_from_text(text, town=town), town)   # E-A is reachable again later


@pytest.mark.parametrize(("formula", "mixed"), [
    ("v1 & v2 U v3", True), ("v2 U v3 | v1", True), ("(v1 & v2) U v3", False),
    ("v1 & (v2 U v3)", False), ("F (v1 & F v2)", False), ("(!v1) U (v2 & F v3)", False),
    ("F (v1 & v2 U v3)", True),
])
def test_precedence_warning_when_and_or_meet_until_without_parentheses(town, formula, mixed):
    states = {"v1": ["B-G"], "v2": ["I-J"], "v3": ["K-L"]}
    warnings = lint(spec_from_text(spec_text(formula, states), "<t>", town))
    found = [w for w in warnings if w.code == "precedence"]
    assert bool(found) == mixed
    if mixed:
        assert "U binding tighter than & and |" in found[0].message


def test_threshold_hit_by_a_reachable_belief(town):
    """Under the uniform prior c·b = k/7 at the prior and after every `none` road."""
    states = {"v1": ["B-G"]}
    low = [1, 1, 0, 0, 0, 0, 0]
    on = spec_from_text(spec_text("(!low) U v1", states, {"low": (low, 2 / 7)}), "<t>", town)
    off = spec_from_text(spec_text("(!low) U v1", states, {"low": (low, 0.3)}), "<t>", town)
    hit = [w for w in lint(on, town) if w.code == "threshold-hit"]
    assert len(hit) == 1 and hit[0].atom == "low" and "0.2857142857142857" in hit[0].message
    assert not [w for w in lint(off, town) if w.code == "threshold-hit"]


def test_rejected_at_start_when_the_prior_or_the_start_road_already_breaks_the_until(town):
    """Position 0 is the start road read with the prior: (!low) U v1 rejects there when low holds
    at the uniform prior (c·b = 2/7 > 0.25), or when the start road is itself one of the avoided
    roads; every policy is then worth 0, which the exact evaluation of the free route confirms."""
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.evaluation.plain import evaluate
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.routing.free import trust_free_policy

    pomdp = build_pomdp(town, load_driver_model())
    states, low = {"v1": ["B-G"]}, [1, 1, 0, 0, 0, 0, 0]
    for offset, rejected in ((0.25, True), (0.3, False)):
        spec = spec_from_text(spec_text("(!low) U v1", states, {"low": (low, offset)}), "<t>", town)
        found = [w.message for w in lint(spec, town) if w.code == "rejected-at-start"]
        assert (evaluate(pomdp, spec, trust_free_policy(town, spec)).lower == 0) == rejected
        assert found == ([] if not rejected else [
            "the spec is rejected at position 0, the start road E-A read with the prior belief, so every "
            "policy is worth 0: low (c·b = 0.2857 > 0.25) already holds there"])
    road = spec_from_text(spec_text("(!a) U v1", {**states, "a": ["E-A"]}), "<t>", town)
    (warning,) = [w for w in lint(road, town) if w.code == "rejected-at-start"]
    assert warning.message.endswith("so every policy is worth 0")
