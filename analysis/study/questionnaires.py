"""Questionnaire scores of a live study (questionnaires.parquet): per questionnaire and condition
the mean score, its spread and Cronbach's alpha, and the paired test of the single trust rating
(Wilcoxon signed-rank on each participant's mean score per condition) for every pair of conditions,
Holm-adjusted over the pairs per questionnaire (`wilcoxon_p_holm`), as the paired tables are.

A response's score is the mean of its items, reversed items turned (scale_min + scale_max -
value): Jian et al.'s scale on 1-7 with its five distrust items reversed, raw NASA-TLX on 0-100.
Alpha is computed over every response to the questionnaire after a trial of that condition
(items as columns): k/(k-1) * (1 - sum of item variances / variance of the sum), sample variances.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.formatting import finite_or_none
from trustroute.analysis.statistics import wilcoxon_paired
from trustroute.analysis.study.paired import with_holm
from trustroute.core.dataset import QUESTIONNAIRES_FILE, read_questionnaires
from trustroute.core.package import table_path

KEYS = ["participant", "episode_id", "placement", "questionnaire"]


def cronbach_alpha(items: np.ndarray) -> float | None:
    """Alpha of a responses x items matrix; None with fewer than 2 responses or items, or no spread."""
    if items.ndim != 2 or items.shape[0] < 2 or items.shape[1] < 2:
        return None
    total = items.sum(axis=1).var(ddof=1)
    if total == 0:
        return None
    k = items.shape[1]
    return float(k / (k - 1) * (1 - items.var(axis=0, ddof=1).sum() / total))


def responses(answers: pd.DataFrame) -> tuple[pd.DataFrame, dict[tuple, np.ndarray]]:
    """(one row per response with its score, {response key: its turned item values})."""
    turned = answers.assign(turned=np.where(answers["reversed"], answers["scale_min"] + answers["scale_max"]
                                            - answers["value"], answers["value"]))
    rows, matrices = [], {}
    for key, group in turned.sort_values("item_index").groupby(KEYS, dropna=False, sort=True):
        rows.append(dict(zip(KEYS, key, strict=True)) | {"score": float(group["turned"].mean())})
        matrices[key] = group["turned"].to_numpy(dtype=float)
    return pd.DataFrame(rows), matrices


def questionnaire_tables(study_dir: Path, episodes: pd.DataFrame,
                         pairs: list[tuple[str, str]]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(scores per questionnaire and condition, paired tests per questionnaire and pair of
    conditions); empty frames for a study without questionnaires."""
    if not table_path(study_dir, QUESTIONNAIRES_FILE).exists():
        return pd.DataFrame(), pd.DataFrame()
    scored, matrices = responses(read_questionnaires(study_dir))
    if scored.empty:
        return pd.DataFrame(), pd.DataFrame()
    conditions = episodes.set_index("episode_id")["condition"]
    scored["condition"] = [conditions.get(e, "(before or end)") if isinstance(e, str) else "(before or end)"
                           for e in scored["episode_id"]]
    rows = []
    for (name, condition), group in scored.groupby(["questionnaire", "condition"], sort=True):
        keys = [tuple(row) for row in group[KEYS].itertuples(index=False, name=None)]
        items = np.vstack([matrices[key] for key in keys])
        rows.append({"questionnaire": name, "condition": condition, "responses": len(group),
                     "participants": int(group["participant"].nunique()),
                     "mean_score": float(group["score"].mean()),
                     "sd_score": finite_or_none(group["score"].std(ddof=1)) if len(group) > 1 else None,
                     "cronbach_alpha": cronbach_alpha(items)})
    tests = []
    for a, b in pairs:
        for name, group in scored[scored["condition"].isin((a, b))].groupby("questionnaire", sort=True):
            wide = group.pivot_table(index="participant", columns="condition", values="score", aggfunc="mean")
            if a in wide and b in wide:
                wx = wilcoxon_paired(wide[a].to_numpy(dtype=float), wide[b].to_numpy(dtype=float))
                tests.append({"questionnaire": name, "a": a, "b": b, "pairs": wx.pairs,
                              "median_difference": finite_or_none(wx.median_difference),
                              "wilcoxon_p": finite_or_none(wx.p_value), "wilcoxon_method": wx.method})
    return pd.DataFrame(rows), with_holm(pd.DataFrame(tests), ["questionnaire"], ("wilcoxon_p",))
