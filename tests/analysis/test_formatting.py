"""Display formatting shared by the study tables, the real-study text and the CLI."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from trustroute.analysis.formatting import (
    aligned_columns,
    estimate_column,
    finite_or_none,
    format_p,
    interval_column,
    interval_text,
    markdown_table,
    number_text,
)


def test_format_p_is_scientific():
    assert format_p(3.05e-7) == "3.05e-07"
    assert format_p(1.0) == "1.00e+00"
    assert format_p(None) == "-"
    assert format_p(math.nan) == "-"


def test_missing_values_are_none_or_a_dash():
    for missing in (None, math.nan, pd.NA, np.float64("nan")):
        assert finite_or_none(missing) is None
        assert number_text(missing) == "-"
    assert finite_or_none(np.float64(0.25)) == 0.25 and type(finite_or_none(np.int64(3))) is float


def test_numbers_and_intervals():
    assert number_text(0.12345) == "0.123" and number_text(np.float32(0.5), 2) == "0.50"
    assert number_text(math.inf) == "inf" and number_text(7) == "7" and number_text("18/21") == "18/21"
    assert interval_text(0.1, 0.25) == "[0.100, 0.250]"
    assert interval_text(None, 0.25) == "-" and interval_text(0.1, math.nan) == "-"
    frame = pd.DataFrame({"v": [0.5, None], "lo": [0.25, 0.1], "hi": [0.75, 0.2]})
    assert interval_column(frame, "lo", "hi", 2) == ["[0.25, 0.75]", "[0.10, 0.20]"]
    assert estimate_column(frame, "v", "lo", "hi") == ["0.500 [0.250, 0.750]", "-"]
    assert estimate_column(frame, "absent", "lo", "hi") == ["-", "-"]


def test_tables_as_markdown_and_aligned_text():
    frame = pd.DataFrame({"a|b": ["x|y", "two\nlines"], "n": [1, 22]})
    assert markdown_table(frame).splitlines() == [
        "| a\\|b | n |", "|---|---|", "| x\\|y | 1 |", "| two lines | 22 |"]
    assert aligned_columns(["name", "n"], [["ab", "1"], ["a", "333"]]) == [
        "name  n", "----  ---", "ab    1", "a     333"]


def test_terminal_tables_fit_120_columns_and_keep_every_cell():
    from trustroute.analysis.formatting import TERMINAL_WIDTH, terminal_table, wrapped_text

    header = ["spec", *[f"column {i} with a long name" for i in range(12)], "note"]
    rows = [[f"phi{r}", *[f"{r}.{i:03d} [0.1, 0.9]" for i in range(12)],
             "a long note explaining why this row's odds ratio is open above " * 2] for r in range(3)]
    wide = terminal_table(header, rows, width=None)
    assert max(len(line) for line in wide) > 300
    lines = terminal_table(header, rows)
    assert TERMINAL_WIDTH == 120 and max(len(line) for line in lines) <= 120
    text = "\n".join(lines)
    for row in rows:
        for cell in row[:-1]:
            assert cell in text  # every cell shown, none cut
    assert " ".join(text.split()).count("odds ratio is open above") == 6  # the note wraps, whole
    assert text.count("phi1") >= 3  # the key column repeats in every block
    assert all(len(line) <= 120 for line in wrapped_text("word " * 100))


def test_a_cell_wrapped_in_one_block_leaves_no_blank_lines_in_the_others():
    """A long note wraps over several lines of its own block; the other blocks show each row on
    one line, so the only blank lines are the one between blocks."""
    from trustroute.analysis.formatting import terminal_table

    header = ["outcome", *[f"estimate of a long name {i}" for i in range(4)], "note"]
    rows = [[f"outcome {r}", *[f"{r}.{i:03d} [0.100, 0.900]" for i in range(4)],
             "complete separation, the one discordant pair favours aware: shown the exact OR " * r]
            for r in (2, 0)]
    lines = terminal_table(header, rows)
    blocks = "\n".join(lines).split("\n\n")
    assert len(blocks) == 2 and all("" not in block.splitlines() for block in blocks), lines
    first = blocks[0].splitlines()
    assert [line.split("  ")[0] for line in first[2:]] == ["outcome 2", "outcome 0"]
    assert " ".join(blocks[1].split()).count("shown the exact OR") == 2


def test_analyze_prints_within_120_columns_unless_wide(model_study):
    from click.testing import CliRunner

    from trustroute.harness.cli import cli

    narrow = CliRunner().invoke(cli, ["analyze", str(model_study), "--no-report"])
    assert narrow.exit_code == 0, narrow.output
    assert max(len(line) for line in narrow.output.splitlines()) <= 120
    wide = CliRunner().invoke(cli, ["analyze", str(model_study), "--no-report", "--wide"])
    assert wide.exit_code == 0 and max(len(line) for line in wide.output.splitlines()) > 120


def test_a_table_that_fits_keeps_its_long_cells_whole():
    from trustroute.analysis.formatting import CELL_WIDTH, terminal_table

    label = "Pr_max(phi1), synthesized, ours within H=20 junctions"
    assert len(label) > CELL_WIDTH
    lines = terminal_table(["figure", "paper", "ours"], [[label, "0.8357", "[0.9989, 0.9999]"]])
    assert len(lines) == 3 and lines[2].startswith(label) and lines[2].endswith("[0.9989, 0.9999]")
    assert all(line == line.rstrip() for line in lines)
