"""`trustroute spec check` end to end: text and JSON output, the dot file, and bad input (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli


def test_phi1_text_output_lists_the_two_warnings(capsys):
    code, out, _ = run_cli(capsys, "spec", "check", "specs/phi1.toml")
    assert code == 0
    assert "DFA: 4 states (1 accepting, 0 rejecting) over 5 atoms" in out
    warnings = [line for line in out.splitlines() if line.startswith("warning")]
    assert len(warnings) == 2
    assert warnings[0].startswith("warning [belief-never-true]: belief atom 'lowtrust'")
    assert warnings[1].startswith("warning [atom-no-effect]: atom 'lowtrust'")


@pytest.mark.parametrize(("name", "states", "warnings"), [
    ("phi1", 4, 2), ("phi2", 4, 2), ("phi1_strict", 5, 0), ("phi2_strict", 5, 0)])
def test_json_output(capsys, name, states, warnings):
    code, out, _ = run_cli(capsys, "spec", "check", f"specs/{name}.toml", "--json")
    assert code == 0
    payload = json.loads(out)
    assert payload["name"] == name
    assert payload["dfa_states"] == states
    assert set(payload["atoms"]) == {"lowtrust", "hightrust"} | {f"v{i}" for i in
                                                                 ((1, 2, 3) if "1" in name else (4, 5, 6))}
    assert len(payload["warnings"]) == warnings
    assert all(set(w) >= {"code", "message"} for w in payload["warnings"])


def test_dot_file(capsys, tmp_path):
    dot = tmp_path / "phi1_strict.dot"
    code, out, _ = run_cli(capsys, "spec", "check", "specs/phi1_strict.toml", "--dot", str(dot))
    assert code == 0 and f"wrote {dot}" in out
    text = dot.read_text()
    assert text.startswith('digraph "phi1_strict"')
    assert text.count("doublecircle") == 1 and "v3 & hightrust" in text and "lowtrust & !v1" in text


def test_bad_formula_exits_2_with_one_line_naming_file_line_column_and_text(capsys, tmp_path):
    spec = tmp_path / "bad.toml"
    text = Path("specs/phi1.toml").read_text().replace("F (v3 & hightrust)", "G (v3 & hightrust)")
    spec.write_text(text)
    code, out, err = run_cli(capsys, "spec", "check", str(spec))
    assert out == ""
    formula_line = next(line for line in text.splitlines() if line.startswith("formula"))
    assert_one_line_error(code, err, f"error: {spec}: line 5 column {formula_line.index('G (v3') + 1} "
                          "(formula): ", "not co-safe", "near 'G (v3 & hightrust))))'")


def test_spec_against_another_town(capsys, tmp_path):
    town = tmp_path / "triangle.json"
    town.write_text(json.dumps({
        "junctions": {"B": [0, 0], "C": [100, 0], "D": [50, 80]},
        "roads": [["B", "C"], ["C", "D"], ["D", "B"]],
        "incidents": {r: "none" for r in ["B-C", "C-B", "C-D", "D-C", "D-B", "B-D"]}}))
    code, _, err = run_cli(capsys, "spec", "check", "specs/phi1.toml", "--town", str(town))
    assert code == 2 and "is not a directed road of the town" in err
    spec = tmp_path / "tri.toml"
    spec.write_text('name = "tri"\nstart = "B-C"\nformula = "F a"\n[states]\na = ["C-B"]\n')
    code, out, _ = run_cli(capsys, "spec", "check", str(spec), "--town", str(town), "--json")
    assert code == 0
    assert [w["code"] for w in json.loads(out)["warnings"]] == ["state-unreachable", "town-unsatisfiable"]


def test_missing_spec_file(capsys, tmp_path):
    code, _, err = run_cli(capsys, "spec", "check", str(tmp_path / "nope.toml"))
    assert code == 2 and "cannot read the spec file" in err


def test_waypoint_distances_in_junctions(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "spec", "check", "specs/phi2_strict.toml")
    assert code == 0
    assert ("waypoints, fewest junctions from the previous: start L-H -> v4 (3 roads): 3 junctions -> "
            "v5 (3 roads): 3 junctions -> v6 (3 roads): 2 junctions") in out
    spec = tmp_path / "far.toml"
    spec.write_text('name = "far"\nstart = "E-A"\nformula = "F (there & F back)"\n[states]\n'
                    'there = {junction = "L"}\nback = ["L-E"]\n')
    code, out, _ = run_cli(capsys, "spec", "check", str(spec), "--json")
    assert code == 0
    assert json.loads(out)["waypoints"] == [
        {"from": "start", "to": "there", "junctions": 3, "roads": 3},  # no U-turn at A: A-F, F-H, H-L
        {"from": "there", "to": "back", "junctions": 1, "roads": 1}]  # K-L (or H-L), then L-E


def test_one_road_and_one_junction_are_said_in_the_singular(capsys, tmp_path):
    """A town of one street (two junctions, as an OpenStreetMap race track imports): the waypoint
    line, the trust-free route and the episode count one road and one junction in the singular."""
    town = tmp_path / "track.json"
    town.write_text(json.dumps({"junctions": {"A": [0, 0], "B": [500, 0]}, "roads": [["A", "B"]],
                                "incidents": {"A-B": "none", "B-A": "none"}}))
    spec = tmp_path / "back.toml"
    spec.write_text('name = "back"\nstart = "A-B"\nformula = "F v"\n[states]\nv = ["B-A"]\n')
    code, out, err = run_cli(capsys, "spec", "check", str(spec), "--town", str(town))
    assert code == 0 and "start A-B -> v (1 road): 1 junction" in out, err
    code, out, err = run_cli(capsys, "baseline", str(spec), "--town", str(town))
    assert code == 0 and "back trust-free route (1 junction, 500 m): A-B B-A" in out, err
    code, out, err = run_cli(capsys, "run", str(spec), "--town", str(town), "--policy", "free")
    assert code == 0 and out.startswith("back-free-s0: accepted after 1 junction, satisfied=True"), err
