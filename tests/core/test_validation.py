"""The guarded reader accepts what real files contain (the bad-input matrix covers what it refuses)."""

from __future__ import annotations

import pytest

from trustroute.core.errors import InputError
from trustroute.core.validation import MAX_DEPTH, check_keys, parse_json, parse_toml, read_input_text


def test_ordinary_values_pass():
    data = parse_json('{"a": [1.5, -2, 1e300, 123456789012345678], "b": "ü\\u00e9"}', "x", "file")
    assert data == {"a": [1.5, -2, 1e300, 123456789012345678], "b": "üé"}
    assert parse_toml('a = inf\nb = "[[[[ not nesting"  # [[[\nc = 0xff_ff\n[t]\nd = 1979-05-27', "x",
                      "file")["a"] == float("inf")


def test_nesting_limit_is_exact():
    assert parse_json("[" * MAX_DEPTH + "]" * MAX_DEPTH, "x", "file") == parse_json(
        "[" * MAX_DEPTH + "]" * MAX_DEPTH, "x", "file")
    with pytest.raises(InputError, match="nested 65 levels"):
        parse_json("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), "x", "file")
    brackets_in_strings = '{"s": "' + "[" * 1000 + '"}'
    assert parse_json(brackets_in_strings, "x", "file")["s"] == "[" * 1000


def test_utf8_text_reads_back(tmp_path):
    path = tmp_path / "f.json"
    path.write_text("{}", encoding="utf-8")
    assert read_input_text(path, "file") == "{}"


def test_unknown_key_names_the_key_and_the_allowed_ones():
    with pytest.raises(InputError) as error:
        check_keys({"junctions": 1, "junctoins": 2}, ("junctions", "roads"), "town.json", "", "town file")
    assert error.value.place == "junctoins" and "junctions, roads" in error.value.fix


LONG_KEYS = tuple(f"setting_number_{i}" for i in range(30)) + ("seed",)


@pytest.mark.parametrize(("key", "start"), [("sede", "write seed, the closest key, or another key of the "
                                             "test config docs/input_files.md lists"),
                                            ("xyzzy", "use only the keys of the test config "
                                             "docs/input_files.md lists")])
def test_an_unknown_key_among_many_names_the_closest_and_the_doc_uncut(key, start):
    with pytest.raises(InputError) as error:
        check_keys({key: 1}, LONG_KEYS, "c.toml", "study", "test config")
    assert error.value.fix == f"{start} (a misspelt key would be ignored otherwise)"
    assert error.value.one_line().endswith("ignored otherwise))")


@pytest.mark.parametrize("value", [2**63 - 1, -(2**63), 10**18])
def test_every_int64_is_an_integer_of_an_input(value):
    """The documented range (docs/input_files.md) is the signed 64-bit one: 2**63 - 1 is a valid seed."""
    assert parse_json(f'{{"n": {value}}}', "x", "file") == {"n": value}
    assert parse_toml(f"n = {value}", "x", "file") == {"n": value}


@pytest.mark.parametrize("value", [2**63, -(2**63) - 1, 10**19])
def test_integers_beyond_int64_are_refused(value):
    with pytest.raises(InputError, match="out of the 64-bit range|digits"):
        parse_json(f'{{"n": {value}}}', "x", "file")
    with pytest.raises(InputError, match="out of the 64-bit range|digits"):
        parse_toml(f"n = {value}", "x", "file")


@pytest.mark.parametrize(("text", "place", "problem"), [
    ('{"types": [{"name": "a", "weight": NaN}]}', "types[0].weight", "NaN is not a number JSON allows"),
    ('{"types": [{"w": 1}, {"w": -Infinity}]}', "types[1].w", "-Infinity is not a number JSON allows"),
    ('{"types": [{"name": "a", "name": "b"}]}', "types[0].name", "duplicate key 'name' in one object"),
    ('[1, {"a": [2, 1e400]}]', "[1].a[1]", "number 1e400 is out of the floating-point range"),
    ('{"seed": 9999999999999999999}', "seed", "out of the 64-bit range"),
    ("NaN", "top level", "NaN is not a number JSON allows"),
    ('{"a": NaN, "b": {"c": 1, "c": 2}}', "a", "NaN"),   # the first in the file
])
def test_json_refusals_name_the_key(text, place, problem):
    with pytest.raises(InputError) as error:
        parse_json(text, "pop.json", "driver population")
    assert error.value.place == place
    assert problem in error.value.problem


@pytest.mark.parametrize(("text", "place"), [
    ("[population]\ntakeover_spread = nan\n", "population.takeover_spread"),
    ("seed = 1\nweights = [0.5, -nan]\n", "weights[1]"),
    ("[[types]]\nw = 1.0\n[[types]]\nw = nan\n", "types[1].w"),
])
def test_toml_nan_names_the_key(text, place):
    with pytest.raises(InputError) as error:
        parse_toml(text, "cfg.toml", "study config")
    assert error.value.place == place
    assert "is not a number" in error.value.problem


@pytest.mark.parametrize(("parse", "text"), [(parse_json, '{"a": 1}'), (parse_toml, "a = 1")])
def test_a_byte_order_mark_is_named_with_its_fix(parse, text):
    with pytest.raises(InputError) as error:
        parse("\ufeff" + text, "f", "study config")
    assert error.value.place == "line 1 column 1"
    assert error.value.problem == "the study config starts with a UTF-8 byte order mark (BOM)"
    assert error.value.fix == "save the file as UTF-8 without a BOM"


def test_beliefs_are_probability_vectors_within_the_tolerance():
    import numpy as np

    from trustroute.core.validation import BELIEF_TOLERANCE, first_non_belief

    good = np.full((3, 7), 1 / 7)
    assert first_non_belief(good) is None and first_non_belief(np.zeros((0, 7))) is None
    near = good.copy()
    near[1, 0] += BELIEF_TOLERANCE / 2
    assert first_non_belief(near) is None
    for value, problem in ((np.nan, "not a finite number"), (np.inf, "not a finite number"),
                           (-0.1, "outside [0, 1]"), (1 / 7 + 3 * BELIEF_TOLERANCE, "sum to 1.000003")):
        bad = good.copy()
        bad[2, 3] = value
        row, found = first_non_belief(bad)
        assert row == 2 and problem in found


def test_a_csv_row_is_named_by_the_line_an_editor_shows_it_on(tmp_path):
    """Data rows count from 0 after the header, as pandas reads them; blank lines are skipped and a
    quoted cell may span lines, so the line is found in the file, not computed from the row."""
    import pandas as pd

    from trustroute.core.validation import csv_line, csv_place

    path = tmp_path / "log.csv"
    path.write_text('tick,note\n0,a\n\n1,"two\nlines"\n   \n2,c\n')
    lines = path.read_text().splitlines()
    frame = pd.read_csv(path)
    for row in range(len(frame)):
        line = csv_line(path, row)
        assert lines[line - 1].startswith(f"{frame['tick'].iloc[row]},"), (row, line)
    assert [csv_line(path, row) for row in range(3)] == [2, 4, 7]
    assert csv_place(path, 2, "note") == "line 7, column note" and csv_place(path, 0) == "line 2"


@pytest.mark.parametrize(("name", "text"), [
    ("bom", "\ufefftick,note\n0,a\n\n1,b\n2,c\n"),
    ("crlf", 'tick,note\r\n0,a\r\n\r\n1,"x\r\ny"\r\n2,c\r\n'),
    ("cr", "tick,note\r0,a\r\r1,b\r2,c\r"),
    ("blank_lines_before_the_header", "\n\ntick,note\n0,a\n1,b\n2,c\n"),
    ("an_empty_quoted_cell", 'tick,note\n0,a\n""\n1,b\n2,c\n'),
])
def test_a_csv_row_is_found_on_its_line_whatever_the_line_ends(tmp_path, name, text):
    """Each row pandas reads is named by its own line: a BOM, CRLF or CR line ends and blank lines
    before the header move no row; a line holding only an empty quoted cell is a row to pandas (of
    empty cells), not a blank line it skips."""
    import re

    import pandas as pd

    from trustroute.core.validation import csv_line

    path = tmp_path / f"{name}.csv"
    path.write_bytes(text.encode())
    lines = re.split(r"\r\n|\n|\r", path.read_bytes().decode("utf-8-sig"))
    frame = pd.read_csv(path)
    for row, tick in enumerate(frame["tick"]):
        shown = lines[csv_line(path, row) - 1]
        assert shown == '""' if pd.isna(tick) else shown.startswith(f"{int(tick)},"), (row, shown)
