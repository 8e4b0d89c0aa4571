"""The study tables as shown: formatted strings (analysis/formatting.py), one display table per
analysis table, their titles, and the plain-text rendering of `trustroute analyze`.
"""

from __future__ import annotations

from collections.abc import Callable

import pandas as pd

from trustroute.analysis.belief_sources import SIMULATED_ENGINES, beside_source, source_label
from trustroute.analysis.formatting import (
    MISSING,
    TERMINAL_WIDTH,
    bounds_column,
    estimate_column,
    finite_or_none,
    format_p,
    interval_column,
    number_text,
    terminal_table,
    wrapped_text,
)
from trustroute.analysis.statistics import (
    BOOTSTRAP_DEGENERATE,
    BOOTSTRAP_PERCENTILE,
    WILCOXON_APPROXIMATE,
    WILCOXON_EXACT,
)
from trustroute.analysis.study.analysis import MULTIPLICITY, StudyAnalysis
from trustroute.analysis.study.design import order_text
from trustroute.analysis.study.manual import manual_display
from trustroute.core.wording import counted


def paired_display(p: pd.DataFrame) -> pd.DataFrame:
    """Paired statistics as shown (one row per spec and pair; a driver type first when given)."""
    shown = pd.DataFrame(
        {
            "spec": p["spec"],
            "pair": p["condition_a"] + " vs " + p["condition_b"],
            "unit": p["unit"],
            "n": p["pairs"],
            "only A / only B sat.": _counts_column(p, "only_a_satisfied", "only_b_satisfied"),
            "risk difference [95% CI]": named_estimate_column(p, "risk_difference", "rd_low", "rd_high",
                                                              "rd_method"),
            "conditional OR [exact CI]": estimate_column(p, "odds_ratio", "or_low", "or_high", 2),
            "McNemar exact p": [format_p(finite_or_none(v)) for v in p["mcnemar_p"]],
            "McNemar p (Holm)": _p_column(p, "mcnemar_p_holm"),
            "trust difference [BCa CI]": named_estimate_column(
                p, "trust_difference", "trust_diff_low", "trust_diff_high", "trust_diff_method"
            ),
            "Wilcoxon p (trust)": wilcoxon_p_column(p, "wilcoxon_p"),
            "Wilcoxon p (Holm)": wilcoxon_p_column(p, "wilcoxon_p_holm"),
        }
    )
    if "sign_test_p" in p and p["sign_test_p"].notna().any():  # the "all specs" rows' test
        shown["participants ahead A / B"] = _counts_column(p, "a_ahead", "b_ahead")
        shown["sign test p (satisfaction)"] = _p_column(p, "sign_test_p")
        shown["sign test p (Holm)"] = _p_column(p, "sign_test_p_holm")
    notes = p.get("or_note", pd.Series([""] * len(p), index=p.index)).fillna("")
    if notes.astype(bool).any():  # an odds ratio shown is not b / c: say why beside it
        shown["odds ratio note"] = notes.to_numpy()
    if "driver_type" in p:
        shown.insert(0, "driver type", p["driver_type"].to_numpy())
    return shown


def _counts_column(p: pd.DataFrame, first: str, second: str) -> list[str]:
    """Two counts as "a / b" (missing where the row or the table has none)."""
    return [f"{int(a)} / {int(b)}" if number_text(a) != MISSING else MISSING
            for a, b in zip(p.get(first, [None] * len(p)), p.get(second, [None] * len(p)), strict=True)]


def _p_column(p: pd.DataFrame, column: str) -> list[str]:
    """A p-value column as shown (missing where the table has no such column or value)."""
    values = p[column] if column in p else [None] * len(p)
    return [format_p(finite_or_none(v)) for v in values]


APPROXIMATE_MARK = "≈ "
# bootstrap intervals that are not the BCa interval a column's title names (statistics.py
# `mean_difference`): each shown with its method after it, "(percentile)" or "(degenerate)"
NAMED_METHODS = (BOOTSTRAP_PERCENTILE, BOOTSTRAP_DEGENERATE)


def _method_named(texts: list[str], frame: pd.DataFrame, method: str, named: tuple[str, ...]) -> list[str]:
    """Each shown interval followed by its method in parentheses where it is one of `named` (the
    methods the column's title does not name; column `method` of `frame`)."""
    methods = frame[method] if method in frame else [None] * len(frame)
    return [f"{text} ({how})" if how in named and text != MISSING else text
            for text, how in zip(texts, methods, strict=True)]


def named_interval_column(cells: pd.DataFrame, low: str, high: str, method: str, digits: int) -> list[str]:
    """'[low, high]' per row (formatting.py `interval_column`), followed by "(degenerate)" where
    the interval is the point (column `method`): the column's title names the percentile interval."""
    return _method_named(interval_column(cells, low, high, digits), cells, method, (BOOTSTRAP_DEGENERATE,))


def named_estimate_column(p: pd.DataFrame, value: str, low: str, high: str, method: str) -> list[str]:
    """'estimate [low, high]' per row (formatting.py `estimate_column`), followed by the interval's
    method in parentheses where it is one of NAMED_METHODS (column `method`)."""
    return _method_named(estimate_column(p, value, low, high), p, method, NAMED_METHODS)


def wilcoxon_p_column(p: pd.DataFrame, column: str) -> list[str]:
    """A Wilcoxon p-value column as shown: the exact p, or the normal approximation's marked
    APPROXIMATE_MARK (statistics.py `wilcoxon_paired`, beyond WILCOXON_EXACT_PAIRS differences)."""
    methods = p["wilcoxon_method"] if "wilcoxon_method" in p else [WILCOXON_EXACT] * len(p)
    return [(APPROXIMATE_MARK if method == WILCOXON_APPROXIMATE and text != MISSING else "") + text
            for text, method in zip(_p_column(p, column), methods, strict=True)]


def sensitivity_display(s: pd.DataFrame) -> pd.DataFrame:
    """The sensitivity table as shown: one row per (pair, spec), one column per belief source (the
    leading one marked "(primary)") with the satisfaction difference A − B and its 95% interval."""
    shown = s.assign(pair=s["condition_a"] + " − " + s["condition_b"],
                     value=named_estimate_column(s, "risk_difference", "rd_low", "rd_high", "rd_method"),
                     column=[f"{source} (primary)" if primary else source
                             for source, primary in zip(s["source"], s["primary"], strict=True)])
    wide = shown.pivot_table(index=["pair", "spec"], columns="column", values="value", aggfunc="first",
                             sort=False)
    columns = list(dict.fromkeys(shown["column"]))
    return wide.reindex(columns=columns).reset_index().rename_axis(columns=None).fillna(MISSING)


def _rate_columns(frame: pd.DataFrame, rate: str = "satisfaction_rate") -> dict[str, pd.Series]:
    """A rate and its exact interval (columns ci_low, ci_high), as every table of rates shows them."""
    return {"rate": frame[rate].map(number_text), "exact 95% CI": interval_column(frame, "ci_low", "ci_high")}


def _outcome_columns(cells: pd.DataFrame) -> dict[str, pd.Series]:
    """Satisfied count, rate and exact interval, as every per-cell display table shows them."""
    return {"satisfied": cells["satisfied"], **_rate_columns(cells)}


def _group_columns(groups: pd.DataFrame) -> dict[str, pd.Series]:
    """Episodes, satisfaction rate with its exact interval and mean reported trust of a group of
    episodes (a position in the Latin square, a preceding condition)."""
    return {"n": groups["n"], **_rate_columns(groups),
            "mean trust (reported)": groups["mean_trust"].map(number_text)}


# the mean over positions of trust_after: a synthetic driver's hidden trust; a person's stated trust
TRUE_TRUST, STATED_TRUST = "mean true trust", "mean stated trust"


def trust_columns(cells: pd.DataFrame) -> dict[str, pd.Series]:
    """Reported and true trust and takeovers, as every per-cell display table shows them."""
    return {"mean trust (reported)": cells["mean_trust"].map(number_text),
            "trust 95% CI": named_interval_column(cells, "trust_ci_low", "trust_ci_high",
                                                  "trust_ci_method", 2),
            TRUE_TRUST: cells["mean_true_trust"].map(number_text),
            "takeovers / episode": cells["takeovers_per_episode"].map(lambda v: number_text(v, 2))}


def _cell_columns(c: pd.DataFrame, other: str) -> dict[str, pd.Series]:
    """The main table's columns; `other`: the belief source whose rate is shown beside."""
    return {"spec": c["spec"], "condition": condition_marked(c), "n": c["n"], **_outcome_columns(c),
            "Wilson 95% CI": interval_column(c, "wilson_low", "wilson_high"),
            f"rate ({other})": c[f"satisfaction_rate_{other}"].map(number_text),
            "exact value [L, U]": bounds_column(c, "exact_lower", "exact_upper"),
            "synthesized [L, U]": bounds_column(c, "synthesized_lower", "synthesized_upper"),
            **trust_columns(c),
            "junctions": c["mean_junctions"].map(lambda v: number_text(v, 1)),
            "fallback": c["fallback_rate"].map(lambda v: number_text(v, 2))}


FALLBACK_MARK = " (fallback only)"


def condition_marked(cells: pd.DataFrame) -> pd.Series:
    """The condition column, each condition whose policy is only its fallback marked so."""
    marked = cells.get("fallback_only", pd.Series(False, index=cells.index)).fillna(False).astype(bool)
    return cells["condition"].where(~marked, cells["condition"] + FALLBACK_MARK)


def fallback_only_lines(manifest: dict) -> list[str]:
    """One warning per (spec, condition) whose policy has no synthesized decision (the study's
    manifest records them, harness/study/expected.py)."""
    return [f"Warning: the {condition} policy for {spec} has no synthesized decision (0 rows); it is "
            f"only its fallback, {entry['fallback_only']}: the condition marked{FALLBACK_MARK} measures "
            "that fallback, not a synthesized policy."
            for spec, conditions in (manifest.get("expected") or {}).items()
            for condition, entry in conditions.items() if entry.get("fallback_only")]


def _repeated_columns(r: pd.DataFrame) -> dict[str, pd.Series]:
    return {"outcome": r["outcome"], "model": r["model"], "effect of": r["effect_of"],
            "estimate [95% CI]": estimate_column(r, "estimate", "low", "high"),
            "p": pd.Series([format_p(finite_or_none(v)) for v in r["p_value"]], index=r.index),
            "participants": r["participants"], "episodes": r["episodes"], "note": r["note"]}


def _takeover_columns(t: pd.DataFrame) -> dict[str, pd.Series]:
    return {"incident": t["incident"], "condition": t["condition"], "roads": t["roads"],
            "takeovers": t["takeovers"], **_rate_columns(t, "rate")}


def _order_columns(o: pd.DataFrame) -> dict[str, pd.Series]:
    return {"position": o["position"], **_group_columns(o)}


def _carryover_columns(k: pd.DataFrame) -> dict[str, pd.Series]:
    return {"condition": k["condition"], "driven after": k["previous_condition"], **_group_columns(k)}


def _per_type_columns(c: pd.DataFrame) -> dict[str, pd.Series]:
    return {"driver type": c["driver_type"], "participants": c["participants"], "spec": c["spec"],
            "condition": c["condition"], "n": c["n"], **_outcome_columns(c), **trust_columns(c)}


def questionnaire_display(q: pd.DataFrame) -> pd.DataFrame:
    return pd.DataFrame({"questionnaire": q["questionnaire"], "condition": q["condition"],
                         "responses": q["responses"], "participants": q["participants"],
                         "mean score": [number_text(v, 2) for v in q["mean_score"]],
                         "sd": [number_text(v, 2) for v in q["sd_score"]],
                         "Cronbach's alpha": [number_text(v, 2) for v in q["cronbach_alpha"]]})


def questionnaire_test_display(t: pd.DataFrame) -> pd.DataFrame:
    return pd.DataFrame({"questionnaire": t["questionnaire"], "pair": t["a"] + " vs " + t["b"],
                         "n": t["pairs"],
                         "median difference": [number_text(v, 2) for v in t["median_difference"]],
                         "Wilcoxon p": wilcoxon_p_column(t, "wilcoxon_p"),
                         "Wilcoxon p (Holm)": wilcoxon_p_column(t, "wilcoxon_p_holm")})


def display_tables(analysis: StudyAnalysis) -> dict[str, pd.DataFrame]:
    """The tables as shown (formatted strings, p-values in scientific notation), by name; a table
    without rows is left out."""
    other = beside_source(analysis.belief_source)
    shown: dict[str, tuple[pd.DataFrame, Callable[[pd.DataFrame], pd.DataFrame]]] = {
        "cells": (analysis.cells, lambda c: pd.DataFrame(_cell_columns(c, other))),
        "paired": (analysis.paired, paired_display),
        "repeated": (analysis.repeated, lambda r: pd.DataFrame(_repeated_columns(r))),
        "takeovers": (analysis.takeovers, lambda t: pd.DataFrame(_takeover_columns(t))),
        "order": (analysis.order, lambda o: pd.DataFrame(_order_columns(o))),
        "carryover": (analysis.carryover, lambda k: pd.DataFrame(_carryover_columns(k))),
        "per_type": (analysis.per_type, lambda c: pd.DataFrame(_per_type_columns(c))),
        "per_type_paired": (analysis.per_type_paired, paired_display),
        "questionnaires": (analysis.questionnaires, questionnaire_display),
        "questionnaire_tests": (analysis.questionnaire_tests, questionnaire_test_display),
        "sensitivity": (analysis.sensitivity, sensitivity_display),
        "manual": (analysis.manual, manual_display),
        "paper": (analysis.paper, lambda paper: paper),
    }
    tables = {name: show(frame) for name, (frame, show) in shown.items() if len(frame)}
    if analysis.manifest.get("engine") in SIMULATED_ENGINES:
        return tables
    # people: the trust columns hold what each participant stated (docs/live_studies.md, "Log columns")
    return {name: table.rename(columns={TRUE_TRUST: STATED_TRUST}) for name, table in tables.items()}


TABLE_TITLES = {
    "cells": "Satisfaction and trust per spec and condition",
    "paired": "Paired effects over participants",
    "repeated": "Repeated-measures models (one group per participant, all specs)",
    "takeovers": "Takeover rate per incident type and condition",
    "order": "Order effects: by position in each participant's order",
    "carryover": "Carry-over: by the condition driven just before",
    "per_type": "Satisfaction and trust per true driver type",
    "per_type_paired": "Paired effects per true driver type (every pair of conditions)",
    "questionnaires": "Questionnaire scores per condition (mean of items, reversed items turned)",
    "questionnaire_tests": "Questionnaire scores: paired over participants",
    "sensitivity": "Sensitivity: satisfaction difference A − B [95% CI] on every belief source",
    "manual": "Manual driving per incident type and condition (the takeovers' measures)",
    "paper": "The paper beside this study",
}


# tables whose figures do not depend on the belief source (the others name it in their title)
SOURCE_FREE_TABLES = ("takeovers", "sensitivity", "manual", "questionnaires", "questionnaire_tests")


def table_title(name: str, belief_source: str) -> str:
    """A table's title, naming the belief source its satisfaction figures are evaluated on."""
    if name in SOURCE_FREE_TABLES:
        return TABLE_TITLES[name]
    return f"{TABLE_TITLES[name]} (beliefs: {belief_source})"


# columns that identify a row: repeated in every block of a table split to fit the terminal
KEY_COLUMNS = ("driver type", "spec", "condition", "pair", "incident", "outcome")


def format_table(analysis: StudyAnalysis, width: int | None = TERMINAL_WIDTH) -> str:
    """Plain-text tables for the terminal, fitted to `width` columns (None: as wide as they are)."""
    lines = wrapped_text(
        f"study {analysis.manifest.get('study')} ({analysis.manifest.get('engine')} engine); "
        f"satisfaction on beliefs from: {analysis.belief_source} ({source_label(analysis.belief_source)})",
        width)
    for warning in fallback_only_lines(analysis.manifest):
        lines += wrapped_text(warning, width)
    if analysis.source_note:
        lines += wrapped_text(f"Note: {analysis.source_note}.", width)
    for name, table in display_tables(analysis).items():
        keys = next((i for i, c in enumerate(table.columns) if c not in KEY_COLUMNS), len(table.columns))
        header = [str(c) for c in table.columns]
        lines += ["", table_title(name, analysis.belief_source),
                  *terminal_table(header, table.values.tolist(), width, max(1, keys))]
        if name == "paired":
            lines += wrapped_text(f"Multiplicity: {MULTIPLICITY}.", width)
        if name == "order" and analysis.order_tests:   # under its table, as the report has it
            lines += wrapped_text(order_test_line(analysis.order_tests), width)
    if analysis.paper_note:
        lines += ["", *wrapped_text(analysis.paper_note, width)]
    return "\n".join(lines)


def order_test_line(tests: dict) -> str:
    """The order tests as a sentence; for a fixed order, why there are none."""
    if tests.get("fixed_order"):
        return (f"Every participant drove the cells in one fixed order ({order_text(tests['fixed_order'])}): "
                "position is confounded with spec and condition, so the rows by position are the cells in "
                "session order and the carry-over rows follow the same sequence; no order effect is "
                "estimable (Cochran's Q and Friedman across positions would compare the cells, not orders).")
    participants = tests.get("participants", 0)
    friedman = tests.get("friedman_participants", participants)
    within = "" if friedman == participants else f", within the {friedman} with a report at every position"
    cochran_note, friedman_note = tests.get("cochran_q_note", ""), tests.get("friedman_note", "")
    if cochran_note and cochran_note == friedman_note:
        return (f"Across positions within {counted(participants, 'participant')}: no Cochran's Q or "
                f"Friedman p ({cochran_note}).")
    return (
        f"Across positions within {counted(participants, 'participant')}: Cochran's Q p = "
        f"{format_p(tests.get('cochran_q_p'))} (satisfaction{_reason(cochran_note)}), Friedman p = "
        f"{format_p(tests.get('friedman_p'))} (reported trust{within}{_reason(friedman_note)})."
    )


def _reason(note: str) -> str:
    """Why a p-value is missing, after its outcome's name."""
    return f"; {note}" if note else ""
