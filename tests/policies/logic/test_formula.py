"""scLDTL parser: precedence, round-trips, canonical form, and every listed error with its position."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from trustroute.core.errors import InputError
from trustroute.policies.logic.formula import (
    FALSE,
    TRUE,
    And,
    Const,
    Eventually,
    FormulaError,
    Literal,
    Next,
    Or,
    Until,
    atoms_in_order,
    canonical,
    format_formula,
    make_and,
    make_or,
    make_until,
    parse_formula,
)

a, b, c = Literal("a"), Literal("b"), Literal("c")


@pytest.mark.parametrize(("text", "expected"), [
    ("a", a),
    ("!a", Literal("a", False)),
    ("!(a)", Literal("a", False)),
    ("!!a", a),
    ("!true", FALSE),
    ("true & false", And((TRUE, FALSE))),
    ("a & b | c", Or((And((a, b)), c))),
    ("a | b & c", Or((a, And((b, c))))),
    ("a & b & c", And((a, b, c))),
    ("a & (b & c)", And((a, And((b, c))))),
    ("a U b U c", Until(a, Until(b, c))),
    ("(a U b) U c", Until(Until(a, b), c)),
    ("a & b U c", And((a, Until(b, c)))),
    ("F a U b", Until(Eventually(a), b)),
    ("X F !a", Next(Eventually(Literal("a", False)))),
    ("F (a & X b)", Eventually(And((a, Next(b))))),
    ("  (( a ))  ", a),
])
def test_parse_precedence(text, expected):
    assert parse_formula(text) == expected


def test_paper_formula_parses_as_written():
    formula = parse_formula("(!lowtrust) U (F (v1 & F (v2 & F (v3 & hightrust))))")
    assert isinstance(formula, Until)
    assert formula.left == Literal("lowtrust", False)
    assert atoms_in_order(formula) == ("lowtrust", "v1", "v2", "v3", "hightrust")
    assert parse_formula(format_formula(formula)) == formula


ATOMS = st.sampled_from(["a", "b", "c", "v1", "hightrust"])


def formulas(max_leaves: int = 12, constants: bool = True):
    literals = st.builds(Literal, ATOMS, st.booleans())
    leaves = st.one_of(st.builds(Const, st.booleans()), literals) if constants else literals

    def extend(children):
        pair = st.lists(children, min_size=2, max_size=3).map(tuple)
        return st.one_of(st.builds(And, pair), st.builds(Or, pair), st.builds(Next, children),
                         st.builds(Eventually, children), st.builds(Until, children, children))

    return st.recursive(leaves, extend, max_leaves=max_leaves)


@settings(max_examples=300, deadline=None)
@given(formulas())
def test_format_then_parse_round_trips(formula):
    text = format_formula(formula)
    assert parse_formula(text) == formula
    assert format_formula(parse_formula(text)) == text


@settings(max_examples=200, deadline=None)
@given(formulas())
def test_canonical_form_is_idempotent_and_parses_back(formula):
    once = canonical(formula)
    assert canonical(once) == once
    assert parse_formula(format_formula(once)) == once


def test_canonical_simplifications():
    na = Literal("a", False)
    assert make_and([a, na]) == FALSE
    assert make_or([a, na]) == TRUE
    assert make_and([a, make_or([a, b])]) == a            # absorption
    assert make_or([a, make_and([a, b])]) == a
    assert make_and([b, a, TRUE, a]) == make_and([a, b])  # unit, duplicates, order
    assert make_until(TRUE, a) == Eventually(a)
    assert make_until(FALSE, a) == a
    assert make_until(a, TRUE) == TRUE
    assert canonical(parse_formula("F F (a & true)")) == Eventually(a)
    assert canonical(parse_formula("X false | F false")) == FALSE


def error_for(text: str, atoms=("a", "b", "v1")) -> FormulaError:
    with pytest.raises(FormulaError) as info:
        parse_formula(text, known_atoms=set(atoms), source="spec.toml", line=5, column=12)
    assert isinstance(info.value, InputError)
    return info.value


@pytest.mark.parametrize(("text", "offset", "words"), [
    ("F (a & v9)", 7, ["unknown atom 'v9'", "expected one of", "a, b, v1"]),
    ("G a", 0, ["'G'", "not co-safe"]),
    ("a & G b", 4, ["'G'", "not co-safe"]),
    ("!(a & b)", 0, ["negation of a compound formula", "not co-safe"]),
    ("!F a", 0, ["negation of a compound formula", "not co-safe"]),
    ("!X a", 0, ["negation of a compound formula"]),
    ("(a & F b", 8, ["unbalanced parentheses", "expected ')'", "column 12"]),
    ("((a)", 4, ["unbalanced parentheses", "expected ')'"]),
    ("a & b)", 5, ["unbalanced parentheses", "')' without a matching '('"]),
    ("", 0, ["empty formula", "expected a formula"]),
    ("   ", 0, ["empty formula"]),
    ("a b", 2, ["expected an operator", "found 'b'"]),
    ("a &", 3, ["expected a formula", "end of the formula"]),
    ("a U", 3, ["expected a formula"]),
    ("()", 1, ["expected a formula before ')'"]),
    ("a && b", 2, ["'&&'", "expected '&'"]),
    ("a -> b", 2, ["implication"]),
    ("a $ b", 2, ["unexpected character '$'"]),
])
def test_parse_errors_name_line_column_and_expectation(text, offset, words):
    error = error_for(text)
    assert error.offset == offset
    assert error.line == 5 and error.column == 12 + offset
    message = error.one_line()
    assert "\n" not in message
    assert message.startswith(f"spec.toml: line 5 column {12 + offset} (formula): ")
    for word in words:
        assert word in message
    # the formula from the offending character on ends the problem (nothing past the end of the text)
    rest = text[offset:].strip()
    if rest:
        assert error.problem.endswith(f", near '{rest}'")
    else:
        assert "near '" not in message


def test_the_text_near_an_error_is_cut_short():
    error = error_for("a $ " + " & ".join(["b"] * 30))
    assert error.problem.endswith(", near '$ b & b & b & b & b &...'")


def test_unknown_atom_is_accepted_without_an_atom_list():
    assert parse_formula("F zz") == Eventually(Literal("zz"))
