"""The study tables as shown: formatted strings (analysis/formatting.py), one display table per
analysis table, their titles, and the plain-text rendering of `trustroute analyze`.
"""

from __future__ import annotations

import pandas as pd

from trustroute.analysis.belief_sources import beside_source, source_label
from trustroute.analysis.formatting import (
    MISSING,
    TERMINAL_WIDTH,
    estimate_column,
    finite_or_none,
    format_p,
    interval_column,
    number_text,
    terminal_table,
    wrapped_text,
)
from trustroute.analysis.study.analysis import StudyAnalysis


def paired_display(p: pd.DataFrame) -> pd.DataFrame:
    """Paired statistics as shown (one row per spec and pair; a driver type first when given)."""
    shown = pd.DataFrame(
        {
            "spec": p["spec"],
            "pair": p["condition_a"] + " vs " + p["condition_b"],
            "unit": p["unit"],
            "n": p["pairs"],
            "only A / only B sat.": [
                f"{int(a)} / {int(b)}" if number_text(a) != MISSING else MISSING
                for a, b in zip(
                    p.get("only_a_satisfied", [None] * len(p)),
                    p.get("only_b_satisfied", [None] * len(p)),
                    strict=True,
                )
            ],
            "risk difference [95% CI]": estimate_column(p, "risk_difference", "rd_low", "rd_high"),
            "conditional OR [exact CI]": estimate_column(p, "odds_ratio", "or_low", "or_high", 2),
            "McNemar exact p": [format_p(finite_or_none(v)) for v in p["mcnemar_p"]],
            "trust difference [BCa CI]": estimate_column(
                p, "trust_difference", "trust_diff_low", "trust_diff_high"
            ),
            "Wilcoxon p (trust)": [format_p(finite_or_none(v)) for v in p["wilcoxon_p"]],
        }
    )
    notes = p.get("or_note", pd.Series([""] * len(p), index=p.index)).fillna("")
    if notes.astype(bool).any():  # an odds ratio shown is not b / c: say why beside it
        shown["odds ratio note"] = notes.to_numpy()
    if "driver_type" in p:
        shown.insert(0, "driver type", p["driver_type"].to_numpy())
    return shown


def _outcome_columns(cells: pd.DataFrame) -> dict[str, pd.Series]:
    """Satisfied count, rate and exact interval, as every per-cell display table shows them."""
    return {"satisfied": cells["satisfied"], "rate": cells["satisfaction_rate"].map(number_text),
            "exact 95% CI": interval_column(cells, "ci_low", "ci_high")}


def _trust_columns(cells: pd.DataFrame) -> dict[str, pd.Series]:
    """Reported and true trust and takeovers, as every per-cell display table shows them."""
    return {"mean trust (reported)": cells["mean_trust"].map(number_text),
            "trust 95% CI": interval_column(cells, "trust_ci_low", "trust_ci_high", 2),
            "mean true trust": cells["mean_true_trust"].map(number_text),
            "takeovers / episode": cells["takeovers_per_episode"].map(lambda v: number_text(v, 2))}


def display_tables(analysis: StudyAnalysis) -> dict[str, pd.DataFrame]:
    """The tables as shown (formatted strings, p-values in scientific notation), by name."""
    other = beside_source(analysis.belief_source)
    tables: dict[str, pd.DataFrame] = {}
    c = analysis.cells
    if len(c):
        tables["cells"] = pd.DataFrame(
            {
                "spec": c["spec"],
                "condition": c["condition"],
                "n": c["n"],
                **_outcome_columns(c),
                "Wilson 95% CI": interval_column(c, "wilson_low", "wilson_high"),
                f"rate ({other})": c[f"satisfaction_rate_{other}"].map(number_text),
                "exact value [L, U]": interval_column(c, "exact_lower", "exact_upper"),
                "synthesized [L, U]": interval_column(c, "synthesized_lower", "synthesized_upper"),
                **_trust_columns(c),
                "junctions": c["mean_junctions"].map(lambda v: number_text(v, 1)),
                "fallback": c["fallback_rate"].map(lambda v: number_text(v, 2)),
            }
        )
    if len(analysis.paired):
        tables["paired"] = paired_display(analysis.paired)
    r = analysis.repeated
    if len(r):
        tables["repeated"] = pd.DataFrame(
            {
                "outcome": r["outcome"],
                "model": r["model"],
                "effect of": r["effect_of"],
                "estimate [95% CI]": estimate_column(r, "estimate", "low", "high"),
                "p": [format_p(finite_or_none(v)) for v in r["p_value"]],
                "participants": r["participants"],
                "episodes": r["episodes"],
                "note": r["note"],
            }
        )
    t = analysis.takeovers
    if len(t):
        tables["takeovers"] = pd.DataFrame(
            {
                "incident": t["incident"],
                "condition": t["condition"],
                "roads": t["roads"],
                "takeovers": t["takeovers"],
                "rate": t["rate"].map(number_text),
                "exact 95% CI": interval_column(t, "ci_low", "ci_high"),
            }
        )
    o = analysis.order
    if len(o):
        tables["order"] = pd.DataFrame(
            {
                "position": o["position"],
                "n": o["n"],
                "rate": o["satisfaction_rate"].map(number_text),
                "exact 95% CI": interval_column(o, "ci_low", "ci_high"),
                "mean trust (reported)": o["mean_trust"].map(number_text),
            }
        )
    k = analysis.carryover
    if len(k):
        tables["carryover"] = pd.DataFrame(
            {
                "condition": k["condition"],
                "driven after": k["previous_condition"],
                "n": k["n"],
                "rate": k["satisfaction_rate"].map(number_text),
                "exact 95% CI": interval_column(k, "ci_low", "ci_high"),
                "mean trust (reported)": k["mean_trust"].map(number_text),
            }
        )
    c = analysis.per_type
    if len(c):
        tables["per_type"] = pd.DataFrame(
            {
                "driver type": c["driver_type"],
                "participants": c["participants"],
                "spec": c["spec"],
                "condition": c["condition"],
                "n": c["n"],
                **_outcome_columns(c),
                **_trust_columns(c),
            }
        )
    if len(analysis.per_type_paired):
        tables["per_type_paired"] = paired_display(analysis.per_type_paired)
    if len(analysis.paper):
        tables["paper"] = analysis.paper
    return tables


TABLE_TITLES = {
    "cells": "Satisfaction and trust per spec and condition",
    "paired": "Paired effects over participants",
    "repeated": "Repeated-measures models (one group per participant, both specs)",
    "takeovers": "Takeover rate per incident type and condition",
    "order": "Order effects: by position in the Latin square",
    "carryover": "Carry-over: by the condition driven just before",
    "per_type": "Satisfaction and trust per true driver type",
    "per_type_paired": "Paired effects per true driver type (every pair of conditions)",
    "paper": "The paper beside this study",
}


# columns that identify a row: repeated in every block of a table split to fit the terminal
KEY_COLUMNS = ("driver type", "spec", "condition", "pair", "incident", "outcome")


def format_table(analysis: StudyAnalysis, width: int | None = TERMINAL_WIDTH) -> str:
    """Plain-text tables for the terminal, fitted to `width` columns (None: as wide as they are)."""
    lines = wrapped_text(
        f"study {analysis.manifest.get('study')} ({analysis.manifest.get('engine')} engine); "
        f"satisfaction on beliefs from: {analysis.belief_source} ({source_label(analysis.belief_source)})",
        width)
    for name, table in display_tables(analysis).items():
        keys = next((i for i, c in enumerate(table.columns) if c not in KEY_COLUMNS), len(table.columns))
        header = [str(c) for c in table.columns]
        lines += ["", TABLE_TITLES[name], *terminal_table(header, table.values.tolist(), width, max(1, keys))]
    if analysis.order_tests:
        lines += wrapped_text(order_test_line(analysis.order_tests), width)
    if analysis.paper_note:
        lines += ["", *wrapped_text(analysis.paper_note, width)]
    return "\n".join(lines)


def order_test_line(tests: dict) -> str:
    return (
        f"Across positions within {tests.get('participants', 0)} participants: Cochran's Q p = "
        f"{format_p(tests.get('cochran_q_p'))} (satisfaction), Friedman p = "
        f"{format_p(tests.get('friedman_p'))} (reported trust)."
    )
