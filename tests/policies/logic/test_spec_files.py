"""Spec files: the four shipped specs, the schema's errors (with file, line, column), identity, projection."""

from __future__ import annotations

from pathlib import Path

import pytest

from trustroute.core.errors import InputError
from trustroute.policies.logic.formula import Eventually, Literal, canonical, format_formula, parse_formula
from trustroute.policies.logic.spec import BeliefAtom, load_spec, spec_from_text, state_only_projection

PHI1_TEXT = Path("specs/phi1.toml").read_text()
PAPER_FORMULA = "(!lowtrust) U (F (v1 & F (v2 & F (v3 & hightrust))))"


def test_phi1_as_in_the_paper(town):
    spec = load_spec("specs/phi1.toml", town)
    assert spec.name == "phi1" and spec.start == "E-A"
    assert spec.formula_text == PAPER_FORMULA
    assert spec.formula == parse_formula(PAPER_FORMULA)
    assert spec.state_atoms == {"v1": frozenset({"B-G", "F-G", "I-G"}),
                                "v2": frozenset({"I-J", "C-J", "K-J"}),
                                "v3": frozenset({"K-L", "E-L", "H-L"})}
    assert spec.belief_atoms == {"hightrust": BeliefAtom((0, 0, 0, 0, 0, 1.0, 1.0), 0.5),
                                 "lowtrust": BeliefAtom((1.0, 0, 0, 0, 0, 0, 0), 1.0)}
    assert spec.atoms == ("v1", "v2", "v3", "hightrust", "lowtrust")
    assert spec.source_path == "specs/phi1.toml"


def test_phi2_as_in_the_paper(town):
    spec = load_spec("specs/phi2.toml", town)
    assert spec.start == "L-H"
    assert spec.formula == parse_formula(PAPER_FORMULA.replace("v1", "v4").replace("v2", "v5")
                                         .replace("v3", "v6"))
    assert spec.state_atoms == {"v4": frozenset({"A-B", "G-B", "C-B"}),
                                "v5": frozenset({"D-K", "J-K", "L-K"}),
                                "v6": frozenset({"A-E", "D-E", "L-E"})}
    assert spec.belief_atoms == load_spec("specs/phi1.toml").belief_atoms


@pytest.mark.parametrize(("name", "paper"), [("phi1_strict", "phi1"), ("phi2_strict", "phi2")])
def test_strict_variants(town, name, paper):
    spec, original = load_spec(f"specs/{name}.toml", town), load_spec(f"specs/{paper}.toml", town)
    v = sorted(original.state_atoms)
    assert spec.formula == parse_formula(f"(!lowtrust) U ({v[0]} & F ({v[1]} & F ({v[2]} & hightrust)))")
    assert spec.start == original.start and spec.state_atoms == original.state_atoms
    assert spec.belief_atoms["lowtrust"] == BeliefAtom((1, 1, 0, 0, 0, 0, 0), 0.3)  # P(trust <= 2) > 0.3
    assert spec.belief_atoms["hightrust"] == original.belief_atoms["hightrust"]


def test_packaged_spec_directory_is_the_specs_symlink():
    assert Path("specs").resolve() == (Path("trustroute") / "core" / "specs").resolve()
    assert sorted(p.stem for p in Path("specs").glob("*.toml")) == [
        "city5", "csomor5", "phi1", "phi1_strict", "phi1_trust", "phi2", "phi2_strict"]


def test_content_hash_ignores_formatting_but_not_meaning():
    spec = spec_from_text(PHI1_TEXT)
    reformatted = (PHI1_TEXT.replace(PAPER_FORMULA, "(!lowtrust)   U(F(v1&F(v2&F(v3&hightrust))))")
                   .replace('["B-G", "F-G", "I-G"]', '["I-G", "B-G", "F-G"]')
                   .replace("offset = 1\n", "offset = 1.0\n")
                   .replace('name = "phi1"', 'name = "renamed"'))
    assert spec_from_text(reformatted).content_hash == spec.content_hash
    changed = PHI1_TEXT.replace("offset = 0.5", "offset = 0.6")
    assert spec_from_text(changed).content_hash != spec.content_hash
    moved = PHI1_TEXT.replace('start = "E-A"', 'start = "A-E"')
    assert spec_from_text(moved).content_hash != spec.content_hash


def test_state_only_projection_drops_every_belief_literal():
    projected = state_only_projection(spec_from_text(PHI1_TEXT))
    assert projected.belief_atoms == {}
    # (true) U F (v1 & F (v2 & F (v3 & true))) = F (v1 & F (v2 & F v3))
    assert projected.formula == canonical(Eventually(parse_formula("v1 & F (v2 & F v3)")))
    assert parse_formula(projected.formula_text) == projected.formula
    strict = state_only_projection(load_spec("specs/phi1_strict.toml"))
    assert format_formula(strict.formula) == "F (F (F v3 & v2) & v1)"
    assert Literal("lowtrust", False) not in list(_literals(strict.formula))


def _literals(formula):
    from trustroute.policies.logic.formula import walk
    return [n for n in walk(formula) if isinstance(n, Literal)]


def error(text: str, town=None) -> str:
    with pytest.raises(InputError) as info:
        spec_from_text(text, "bad.toml", town)
    return info.value.one_line()


def test_unknown_atom_names_file_line_and_column():
    message = error(PHI1_TEXT.replace("F (v3 & hightrust)", "F (v9 & hightrust)"))
    line = next(i for i, x in enumerate(PHI1_TEXT.splitlines(), start=1) if x.startswith("formula"))
    column = len('formula = "') + PAPER_FORMULA.index("v3") + 1
    assert message.startswith(f"bad.toml: line {line} column {column} (formula): unknown atom 'v9'")
    assert "\n" not in message and "near 'v9 & hightrust))))'" in message


def test_state_not_in_the_town(town):
    text = PHI1_TEXT.replace('"F-G"', '"F-Z"')
    assert spec_from_text(text).state_atoms["v1"] == {"B-G", "F-Z", "I-G"}  # no town: not checked
    message = error(text, town)
    assert "bad.toml: line 8 column 14 (states.v1)" in message
    assert "'F-Z' is not a directed road of the town" in message
    message = error(PHI1_TEXT.replace('start = "E-A"', 'start = "E-B"'), town)
    assert "line 4" in message and "start road 'E-B'" in message


def test_a_one_way_road_written_the_other_way_round_is_named_the_right_way():
    from tests.networks.test_road_lookup import LOOP
    from trustroute.networks.town import town_from_dict

    loop = town_from_dict(LOOP, "loop.json")   # one way round B-C-D-E
    text = 'name = "x"\nstart = "C-B"\nformula = "F a"\n[states]\na = ["C-D"]\n'
    message = error(text, loop)
    assert "start road 'C-B' is not a directed road of the town (loop.json)" in message
    assert "one-way, driven from B to C: write 'B-C'" in message
    message = error(text.replace('"C-D"', '"D-C"'), loop)
    assert "(states.a): state atom 'a': 'D-C' is not a directed road" in message
    assert "one-way, driven from C to D: write 'C-D'" in message


def test_an_unknown_road_lists_the_roads_leaving_its_first_junction(town):
    message = error(PHI1_TEXT.replace('"F-G"', '"F-Z"'), town)
    assert "(from F: F-A, F-G, F-H)" in message
    message = error(PHI1_TEXT.replace('start = "E-A"', 'start = "E-B"'), town)
    assert "(from E: E-A, E-D, E-L)" in message


@pytest.mark.parametrize("coeffs", ["[1]", "[]"])
def test_coefficients_of_the_wrong_length(coeffs):
    message = error(PHI1_TEXT.replace("coeffs = [1, 0, 0, 0, 0, 0, 0]", f"coeffs = {coeffs}"))
    assert "bad.toml: line 13 column 1 (beliefs.lowtrust)" in message
    assert "expected one per trust level of the driver model" in message


@pytest.mark.parametrize(("atom", "coeffs"), [("lowtrust", "[1, 0, 0, 0, 0, 0, 0]"),
                                             ("hightrust", "[0, 0, 0, 0, 0, 1, 1]")])
def test_coefficients_not_one_per_trust_level_name_their_line(tmp_path, atom, coeffs):
    """Against the driver model's trust levels (load_spec with n_trust), a belief atom's coeffs of
    another length are placed at the line and column of `coeffs = [...]`, as the loader's errors."""
    text = PHI1_TEXT.replace(f"coeffs = {coeffs}", f"coeffs = {coeffs[:-4]}]")
    path = tmp_path / "six.toml"
    path.write_text(text)
    line = text.splitlines().index(f"coeffs = {coeffs[:-4]}]") + 1
    with pytest.raises(InputError) as raised:
        load_spec(path, n_trust=7)
    assert str(raised.value).startswith(f"{path}: line {line} column 1 (beliefs.{atom}): belief atom "
                                        f"'{atom}' has 6 coefficients but the driver model defines 7 "
                                        "trust levels")


@pytest.mark.parametrize(("formula", "words"), [
    ("G v1", ["'G' (globally) is not co-safe"]),
    ("!(v1 & v2)", ["negation of a compound formula is not co-safe"]),
    ("(v1 & F v2", ["unbalanced parentheses", "expected ')'"]),
    ("v1)", ["unbalanced parentheses"]),
    ("", ["empty formula"]),
])
def test_formula_errors_in_a_file(formula, words):
    message = error(PHI1_TEXT.replace(PAPER_FORMULA, formula))
    assert message.startswith("bad.toml: line 5 column ")
    for word in words:
        assert word in message


@pytest.mark.parametrize(("text", "words"), [
    ('name = "x"\nstart = "E-A"\n', ["missing key 'formula'"]),
    ('start = "E-A"\nformula = "true"\n', ["missing key 'name'"]),
    ('name = "x"\nstart = "E-A"\nformula = "true"\nfrobnicate = 1\n', ["line 4", "unknown key 'frobnicate'"]),
    ('name = "x"\nstart = "E-A"\nformula = 3\n', ["line 3", "'formula' must be a string"]),
    ('name = "x"\nstart = "E-A\nformula = "true"\n', ["line 2", "not valid TOML"]),
    ('name = "x"\nstart = "E-A"\nformula = "a"\n[states]\na = "B-G"\n', ["line 5", "must be a list"]),
    ('name = "x"\nstart = "E-A"\nformula = "a"\n[states]\na = ["BG"]\n', ["not a directed road"]),
    ('name = "x"\nstart = "E-A"\nformula = "a"\n[beliefs.a]\ncoeffs = [0,0,0,0,0,0,1]\n',
     ["line 4", "missing 'offset'"]),
    ('name = "x"\nstart = "E-A"\nformula = "a"\n[beliefs.a]\ncoeffs = [0,0,0,0,0,0,true]\noffset = 1\n',
     ["line 5", "finite numbers"]),
    ('name = "x"\nstart = "E-A"\nformula = "a"\n[beliefs.a]\ncoeffs = [0,0,0,0,0,0,1]\noffset = 1\n'
     'scale = 2\n',
     ["line 7", "unknown key 'scale'"]),
    ('name = "x"\nstart = "E-A"\nformula = "a"\n[states]\na = ["B-G"]\n[beliefs.a]\n'
     'coeffs = [0,0,0,0,0,0,1]\noffset = 1\n', ["defined both"]),
    ('name = "x"\nstart = "E-A"\nformula = "F"\n[states]\nF = ["B-G"]\n', ["not a valid atom name"]),
])
def test_schema_errors(text, words):
    message = error(text)
    assert message.startswith("bad.toml: ")
    for word in words:
        assert word in message


def test_missing_file_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="cannot read the spec file"):
        load_spec(tmp_path / "missing.toml")


# -- waypoint sets named by junction or street -------------------------------------------------------

def _by_junction(v1: str, v2: str, v3: str) -> str:
    return PHI1_TEXT.replace('v1 = ["B-G", "F-G", "I-G"]', f'v1 = {{junction = "{v1}"}}').replace(
        'v2 = ["I-J", "C-J", "K-J"]', f'v2 = {{junction = ["{v2}"]}}').replace(
        'v3 = ["K-L", "E-L", "H-L"]', f'v3 = {{junction = "{v3}"}}')


def test_waypoints_by_junction_mean_the_roads_into_it(town):
    text = _by_junction("G", "J", "L")
    assert text != PHI1_TEXT and "junction" in text
    spec = spec_from_text(text, "by_junction.toml", town)
    phi1 = load_spec("specs/phi1.toml", town)
    assert spec.state_atoms == phi1.state_atoms
    assert spec.content_hash == phi1.content_hash  # the identity is the meaning, not the notation
    two = spec_from_text(text.replace('{junction = ["J"]}', '{junction = ["J", "K"]}'), "two.toml", town)
    assert two.state_atoms["v2"] == {"I-J", "C-J", "K-J", "D-K", "J-K", "L-K"}


def test_waypoints_by_street(town):
    from trustroute.networks.town import town_from_dict

    square = town_from_dict({
        "junctions": {"B": [0, 0], "C": [100, 0], "D": [100, 100], "E": [0, 100]},
        "roads": [["B", "C"], ["C", "D"], ["D", "E"], ["E", "B"]],
        "incidents": {r: "none" for r in ["B-C", "C-B", "C-D", "D-C", "D-E", "E-D", "E-B", "B-E"]},
        "geometry": {"C-D": {"shape": [[100, 0], [100, 100]], "street": "East Lane; High Street"},
                     "E-D": {"shape": [[0, 100], [100, 100]], "street": "High Street"}}}, "square.json")
    text = 'name = "s"\nstart = "B-C"\nformula = "F high"\n[states]\nhigh = {street = "high street"}\n'
    assert spec_from_text(text, "s.toml", square).state_atoms == {"high": frozenset({"C-D", "E-D"})}
    with pytest.raises(InputError, match="no road of the town .* is on a street named 'Low Road'"):
        spec_from_text(text.replace("high street", "Low Road"), "s.toml", square)


@pytest.mark.parametrize(("selector", "message"), [
    ('{junction = "Z"}', "'Z' is not a junction of the town"),
    ('{junction = "G", street = "x"}', "exactly one key, junction or street"),
    ('{roads = ["B-G"]}', "exactly one key, junction or street"),
    ("{junction = []}", "must be a name or a non-empty list of names"),
    ("{junction = 3}", "must be a name or a non-empty list of names"),
    ('{street = "Main Street"}', "no road of the town .* is on a street named 'Main Street'"),
])
def test_bad_selectors_name_the_atom_line_and_fix(town, selector, message):
    text = PHI1_TEXT.replace('v1 = ["B-G", "F-G", "I-G"]', f"v1 = {selector}")
    with pytest.raises(InputError, match=message) as info:
        spec_from_text(text, "bad.toml", town)
    assert "state atom 'v1'" in str(info.value) and "line 8" in str(info.value)


@pytest.mark.parametrize(("old", "new"), [
    ('v1 = ["B-G", "F-G", "I-G"]', 'v1 = {junction = "J12"}'),
    ('v1 = ["B-G", "F-G", "I-G"]', 'v1 = {street = "Rudower Chaussee"}'),
    ('v1 = ["B-G", "F-G", "I-G"]', 'v1 = ["-12345#0", "-6789#1"]'),   # a list of an imported town's roads
    ('start = "E-A"', 'start = "-12345#0"'),
])
def test_a_name_of_another_town_names_the_town_option(capsys, tmp_path, old, new):
    """A spec written for an imported town, checked without --town (against the default town):
    whether it names its roads by selector or by list, the fix names --town first, then the names
    the town has."""
    from tests.cli import run_cli

    spec = tmp_path / "drt.toml"
    assert old in PHI1_TEXT
    spec.write_text(PHI1_TEXT.replace(old, new))
    code, _, err = run_cli(capsys, "spec", "check", str(spec))
    assert code == 2 and "(default town)" in err, err
    fix = "(fix: pass the town the spec is written for (--town; in a study config, town in [study]), or "
    assert fix in err, err
    # a study has no --town: its config's key is the door
    config = tmp_path / "study.toml"
    config.write_text('[study]\nparticipants = 1\nseed = 1\nengine = "model"\nspecs = ["drt.toml"]\n'
                      'conditions = ["free"]\n')
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(tmp_path / "out"), "--workers", "1")
    assert code == 2 and "in a study config, town in [study]" in err, err


def test_the_first_bad_atom_in_the_file_is_the_one_reported(town):
    """Atoms are checked in the file's order: 'zeta' (line 5) before 'alpha' (line 6)."""
    text = ('name = "s"\nstart = "E-A"\nformula = "F (zeta & F alpha)"\n[states]\n'
            'zeta = {junction = "Z1"}\nalpha = {street = "Rudower Chaussee"}\n')
    with pytest.raises(InputError, match=r"line 5 column 1 \(states.zeta\): state atom 'zeta'"):
        spec_from_text(text, "s.toml", town)
    good = text.replace('"Z1"', '"G"').replace('{street = "Rudower Chaussee"}', '["I-J"]')
    assert list(spec_from_text(good, "s.toml", town).state_atoms) == ["alpha", "zeta"]


@pytest.mark.parametrize(("tables", "first"), [
    ('[beliefs.zeta]\ncoeffs = [1]\noffset = 0\n[beliefs.alpha]\ncoeffs = [1]\noffset = 0\n',
     r"\(beliefs.zeta\): belief atom 'zeta': coeffs has 1 entry, expected"),
    ('[trust_states]\nzeta = {trust = [9]}\nalpha = {trust = [9]}\n',
     r"\(trust_states.zeta\): trust-state atom 'zeta'"),
    ('[type_beliefs]\nzeta = {types = "x"}\nalpha = {types = "x"}\n',
     r"\(type_beliefs.zeta\): type-belief atom 'zeta'"),
])
def test_every_atom_table_reports_its_first_bad_atom_in_the_file(tables, first):
    """The rule of [states] holds in every atom table: the first error reported is the first in the
    file, whatever the names' order."""
    text = 'name = "s"\nstart = "E-A"\nformula = "F (zeta & F alpha)"\n' + tables
    with pytest.raises(InputError, match=first):
        spec_from_text(text, "s.toml")


def test_a_selector_needs_a_town():
    with pytest.raises(InputError, match="names its roads by junction, which only a town can resolve"):
        spec_from_text(_by_junction("G", "J", "L"), "by_junction.toml")
