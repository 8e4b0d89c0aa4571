"""Trust-state atoms: the [trust_states] table, labels with the hidden trust, traces, projection, lint."""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.core.errors import InputError
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.lint import lint
from trustroute.policies.logic.spec import TrustStateAtom, load_spec, spec_from_text, state_only_projection
from trustroute.policies.logic.trace import evaluate_traces

BASE = '''name = "t"
start = "E-A"
formula = "FORMULA"
[states]
v3 = ["K-L", "E-L", "H-L"]
'''


def spec_text(formula: str, trust_states: str) -> str:
    return BASE.replace("FORMULA", formula) + "[trust_states]\n" + trust_states


def test_trust_state_atoms_parse_with_and_without_roads(town):
    spec = spec_from_text(spec_text("F (v3 & trusting) | F wary",
                                    'trusting = { trust = [6, 7] }\n'
                                    'wary = { roads = ["A-B"], trust = [1, 2] }\n'), town=town)
    assert spec.trust_atoms == {"trusting": TrustStateAtom(frozenset({6, 7})),
                                "wary": TrustStateAtom(frozenset({1, 2}), frozenset({"A-B"}))}
    assert spec.uses_trust_atoms and "wary" in spec.atoms


def test_content_hash_is_unchanged_by_an_empty_table_and_changed_by_an_atom():
    plain = spec_from_text(BASE.replace("FORMULA", "F v3"))
    empty = spec_from_text(BASE.replace("FORMULA", "F v3") + "[trust_states]\n")
    with_atom = spec_from_text(spec_text("F v3", "unused = { trust = [7] }\n"))
    other = spec_from_text(spec_text("F v3", "unused = { trust = [6] }\n"))
    assert plain.content_hash == empty.content_hash != with_atom.content_hash != other.content_hash
    assert not with_atom.uses_trust_atoms


@pytest.mark.parametrize("entry,message", [
    ('x = { roads = ["K-L"] }', "missing 'trust'"),
    ('x = { trust = [0, 7] }', "trust levels (integers 1..7)"),
    ('x = { trust = [] }', "non-empty list"),
    ('x = { trust = [6], level = 2 }', "unknown key 'level'"),
    ('x = { trust = [6], roads = ["Z-Q"] }', "'Z-Q' is not a directed road of the town"),
    ('x = { trust = [6], roads = "K-L" }', "roads must be a list"),
    ('v3 = { trust = [6] }', "defined twice"),
    ('x = [6, 7]', "must be a table"),
])
def test_bad_trust_state_atoms_are_one_line_errors(town, entry, message):
    with pytest.raises(InputError, match=message.replace("(", "\\(").replace(")", "\\)")) as info:
        spec_from_text(spec_text("F v3", entry + "\n"), "bad.toml", town)
    assert "bad.toml" in info.value.one_line() and "\n" not in info.value.one_line()


def test_labels_read_the_trust_level_and_the_road(town):
    spec = spec_from_text(spec_text("F (!wary & trusting)", 'trusting = { trust = [6, 7] }\n'
                                    'wary = { roads = ["K-L"], trust = [1, 2, 3, 4, 5, 6, 7] }\n'), town=town)
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    roads = np.array([town.state_index("K-L"), town.state_index("A-B"), town.state_index("A-B")])
    values = labeller.valuations(roads, np.full((3, 7), 1 / 7), np.array([6, 6, 4]))
    column = {atom: j for j, atom in enumerate(dfa.atoms)}
    assert values[:, column["trusting"]].tolist() == [True, True, False]
    assert values[:, column["wary"]].tolist() == [True, False, False]
    with pytest.raises(ValueError, match="trust level"):
        labeller.valuations(roads, np.full((3, 7), 1 / 7))
    warnings = {w.code for w in lint(spec, town)}
    assert "trust-every-level" in warnings


def test_traces_with_trust_satisfy_on_the_true_trust_only(town):
    spec = load_spec("specs/phi1_trust.toml", town)
    route = ["E-A", "A-B", "B-G", "G-I", "I-J", "J-K", "K-L"]
    states = np.array([[town.state_index(r) for r in route]] * 2)
    beliefs = np.full((2, len(route), 7), 1 / 7)
    trust = np.array([[3] * len(route), [3] * (len(route) - 1) + [5]])   # level 4, then 6 at the end
    result = evaluate_traces(spec, town, states, beliefs, trust=trust)
    assert result.satisfied.tolist() == [False, True]
    assert result.first_accepting.tolist() == [-1, len(route) - 1]


def test_state_only_projection_keeps_the_roads_of_trust_literals(town):
    spec = spec_from_text(spec_text("(!wary) U (v3 & trusting)",
                                    'trusting = { roads = ["K-L"], trust = [6, 7] }\n'
                                    'wary = { trust = [1] }\n'), town=town)
    projected = state_only_projection(spec)
    assert not projected.trust_atoms and projected.state_atoms["trusting"] == frozenset({"K-L"})
    assert projected.formula_text == "F (trusting & v3)"   # true U a = F a
