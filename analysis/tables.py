"""Per-study tables (pandas DataFrames), shared by `trustroute analyze`, the report and real-study figures.

`study_analysis(study_dir, belief_source)` reads a consolidated study directory (episodes.parquet,
roads.parquet, manifest.json) and returns a `StudyAnalysis` whose tables are:

- `cells`: per (spec, condition): n, satisfied, the satisfaction rate with its exact
  (Clopper–Pearson) and Wilson 95 % intervals on the chosen belief source (and the rate on the
  other source), mean reported trust with a bootstrap CI, mean true and final trust, junctions,
  takeovers, fallback rate, the policy's exact value and its synthesized [lower, upper];
- `paired`: per spec, the first two conditions ("aware" vs "free") over participants: the 2x2
  counts, exact McNemar p, the risk difference (Newcombe interval), the conditional odds ratio
  (exact interval), the mean difference in reported trust (BCa bootstrap over participants),
  Wilcoxon p. The "all specs" row is per participant, not per pair: each participant's number of
  specs satisfied under A minus under B, and their trust difference averaged over specs, so 21
  participants count as 21, never as 42 pairs;
- `repeated`: models over every episode with one group per participant: conditional logistic
  regression of satisfaction on the condition with spec fixed effects, and a mixed model of mean
  reported trust with a random intercept per participant (statsmodels);
- `takeovers`: per incident type and condition, roads met, takeovers, rate with exact interval;
- `order`: per position in the Latin square: satisfaction (exact interval) and mean trust, with
  Cochran's Q (satisfaction) and Friedman (trust) across positions within participants;
  `carryover`: per condition and the condition driven just before (same spec or not);
- `per_participant`: one row per participant and spec, the outcomes under each condition;
- `per_type` and `per_type_paired` (studies with a `[drivers] population`, whose episodes carry the
  participant's true `driver_type`): the cells' satisfaction and trust, and the paired statistics
  for every pair of conditions present (free, aware, robust, policy files), per true type and over
  all participants ("all");
- `paper`: the paper's figures beside ours, only when the study is comparable (the paper's town,
  its φ1 and φ2, 21 participants); otherwise `paper_note` says why not.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.satisfaction import BELIEF_SOURCES, episode_satisfaction
from trustroute.analysis.statistics import (
    bootstrap_ci,
    conditional_logit,
    conditional_odds_ratio,
    format_p,
    mcnemar_exact,
    mean_difference,
    mixed_trust_model,
    paired_risk_difference,
    paired_table,
    rate_interval,
    wilcoxon_paired,
)
from trustroute.core.dataset import read_episodes, read_manifest, read_roads
from trustroute.core.errors import InputError

PAPER = {
    "satisfied_aware": {"phi1": (18, 21), "phi2": (17, 21)},
    "satisfaction_rate": {"aware": 0.85, "free": 0.775},
    "mean_trust": {"aware": 4.6018, "free": 4.3933},
    "pr_max": {"phi1": 0.8357, "phi2": 0.7288},
    "participants": 21,
}
ANALYSIS_SEED = 20240513  # bootstrap resampling: fixed, so an analysis is reproducible
ALL_SPECS = "all specs"
ALL_TYPES = "all"


@dataclass
class StudyAnalysis:
    study_dir: Path
    belief_source: str
    manifest: dict
    cells: pd.DataFrame
    paired: pd.DataFrame
    repeated: pd.DataFrame
    takeovers: pd.DataFrame
    order: pd.DataFrame
    order_tests: dict
    carryover: pd.DataFrame
    per_participant: pd.DataFrame
    paper: pd.DataFrame
    paper_note: str
    satisfaction: pd.DataFrame = field(repr=False)  # per episode, both sources
    episodes: pd.DataFrame = field(repr=False)
    per_type: pd.DataFrame = field(default_factory=pd.DataFrame)
    per_type_paired: pd.DataFrame = field(default_factory=pd.DataFrame)

    def to_dict(self) -> dict:
        def records(frame: pd.DataFrame) -> list[dict]:
            return json.loads(frame.to_json(orient="records"))

        return {
            "study_dir": str(self.study_dir),
            "study": self.manifest.get("study"),
            "engine": self.manifest.get("engine"),
            "belief_source": self.belief_source,
            "cells": records(self.cells),
            "paired": records(self.paired),
            "repeated_measures": records(self.repeated),
            "takeovers": records(self.takeovers),
            "order": records(self.order),
            "order_tests": self.order_tests,
            "carryover": records(self.carryover),
            "paper_comparison": records(self.paper),
            "paper_note": self.paper_note,
            "per_type": records(self.per_type),
            "per_type_paired": records(self.per_type_paired),
            "failed_episodes": len(self.manifest.get("failed_episodes", [])),
        }


def _finite(value: object) -> float | None:
    # pd.NA: the mean of a nullable column with no values (e.g. final_trust of real participants)
    if value is None or value is pd.NA:
        return None
    value = float(value)
    return None if math.isnan(value) else value


def load_study(study_dir: Path) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """(manifest, episodes, roads) of a consolidated study, read through trustroute.core.dataset."""
    study_dir = Path(study_dir)
    manifest = read_manifest(study_dir)
    return manifest, read_episodes(study_dir), read_roads(study_dir)


def study_inputs(manifest: dict):
    """(town, nominal driver model, {spec name: Spec}) named by the study's config."""
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec

    config = manifest["config"]
    town = load_town(config.get("town"))
    driver = load_driver_model(config.get("driver_model"))
    specs = {Path(p).stem: load_spec(_spec_path(p), town) for p in config["specs"]}
    return town, driver, specs


def _spec_path(path: str) -> Path:
    """A manifest's spec path; a packaged spec when the recorded path is gone (a study directory
    shipped with the package, or moved to another machine)."""
    from trustroute.core.packaged import PACKAGED_SPECS

    recorded = Path(path)
    packaged = PACKAGED_SPECS / recorded.name
    return recorded if recorded.exists() or not packaged.exists() else packaged


def _pair_conditions(conditions: list[str]) -> tuple[str, str] | None:
    if "aware" in conditions and "free" in conditions:
        return "aware", "free"
    return (conditions[0], conditions[1]) if len(conditions) >= 2 else None


def _reported(values: pd.Series) -> pd.Series:
    """Reported trust as floats with NaN where none was given (null or the older -1)."""
    numeric = pd.to_numeric(values, errors="coerce").astype(float)
    return numeric.where(numeric >= 1)


# -- the tables -------------------------------------------------------------------------------------


def cell_table(
    episodes: pd.DataFrame,
    spec_order,
    condition_order,
    belief_source: str,
    expected: dict,
    rng: np.random.Generator,
    resamples: int,
) -> pd.DataFrame:
    other = [s for s in BELIEF_SOURCES if s != belief_source][0]
    rows = []
    for spec in spec_order:
        for condition in condition_order:
            group = episodes[(episodes["spec"] == spec) & (episodes["condition"] == condition)]
            n = len(group)
            k = int(group[f"satisfied_{belief_source}"].sum())
            low, high = rate_interval(k, n)
            wilson_low, wilson_high = rate_interval(k, n, method="wilson")
            trust = group["mean_reported_trust"].to_numpy(dtype=float)
            trust_low, trust_high = bootstrap_ci(trust, rng, resamples)
            exp = expected.get(spec, {}).get(condition, {})
            rows.append(
                {
                    "spec": spec,
                    "condition": condition,
                    "n": n,
                    "satisfied": k,
                    "satisfaction_rate": k / n if n else None,
                    "ci_low": _finite(low),
                    "ci_high": _finite(high),
                    "wilson_low": _finite(wilson_low),
                    "wilson_high": _finite(wilson_high),
                    f"satisfaction_rate_{other}": _finite(group[f"satisfied_{other}"].mean()) if n else None,
                    "logged_satisfaction_rate": _finite(group["satisfied"].mean()) if n else None,
                    "mean_trust": _finite(np.nanmean(trust)) if np.isfinite(trust).any() else None,
                    "trust_ci_low": _finite(trust_low),
                    "trust_ci_high": _finite(trust_high),
                    "mean_true_trust": _finite(group["mean_trust"].mean()) if n else None,
                    "mean_final_trust": _finite(group["final_trust"].mean()) if n else None,
                    "mean_junctions": _finite(group["junctions"].mean()) if n else None,
                    "takeovers_per_episode": _finite(group["takeovers"].mean()) if n else None,
                    "fallback_rate": _finite(group["fallback_fired"].mean()) if n else None,
                    "exact_lower": exp.get("exact_lower"),
                    "exact_upper": exp.get("exact_upper"),
                    "exact_final_trust": exp.get("expected_final_trust"),
                    "synthesized_lower": exp.get("synthesized_lower"),
                    "synthesized_upper": exp.get("synthesized_upper"),
                    "synthesized_horizon": exp.get("synthesized_horizon"),
                }
            )
    return pd.DataFrame(rows)


def per_participant_table(episodes: pd.DataFrame, column: str, pair: tuple[str, str]) -> pd.DataFrame:
    """One row per (participant, spec): satisfied and mean reported trust under each condition."""
    subset = episodes[episodes["condition"].isin(pair)]
    wide = subset.pivot_table(
        index=["participant", "spec"],
        columns="condition",
        values=[column, "mean_reported_trust"],
        aggfunc="first",
    )
    out = pd.DataFrame(index=wide.index)
    for condition in pair:
        out[f"satisfied_{condition}"] = wide.get((column, condition))
        out[f"trust_{condition}"] = wide.get(("mean_reported_trust", condition))
    return out.reset_index()


def paired_table_rows(
    wide: pd.DataFrame, pair: tuple[str, str], spec_order, rng: np.random.Generator, resamples: int
) -> pd.DataFrame:
    a, b = pair
    rows = []
    for spec in spec_order:
        group = wide[wide["spec"] == spec].dropna(subset=[f"satisfied_{a}", f"satisfied_{b}"])
        if group.empty:
            continue
        first, second = group[f"satisfied_{a}"].astype(bool), group[f"satisfied_{b}"].astype(bool)
        table = paired_table(first, second)
        mc = mcnemar_exact(first, second)
        rd = paired_risk_difference(table)
        odds = conditional_odds_ratio(table)
        trust = mean_difference(group[f"trust_{a}"], group[f"trust_{b}"], rng, resamples)
        wx = wilcoxon_paired(group[f"trust_{a}"], group[f"trust_{b}"])
        rows.append(
            {
                "spec": spec,
                "condition_a": a,
                "condition_b": b,
                "unit": "participant",
                "pairs": table.pairs,
                "both_satisfied": table.both,
                "only_a_satisfied": table.only_first,
                "only_b_satisfied": table.only_second,
                "neither_satisfied": table.neither,
                "mcnemar_p": mc.p_value,
                "risk_difference": _finite(rd.value),
                "rd_low": _finite(rd.low),
                "rd_high": _finite(rd.high),
                "odds_ratio": _finite(odds.value),
                "or_low": _finite(odds.low),
                "or_high": _finite(odds.high),
                "trust_difference": _finite(trust.value),
                "trust_diff_low": _finite(trust.low),
                "trust_diff_high": _finite(trust.high),
                "wilcoxon_pairs": wx.pairs,
                "wilcoxon_p": wx.p_value,
                "median_trust_difference": _finite(wx.median_difference),
            }
        )
    # Across specs, one value per participant (their repeated measures are not independent pairs).
    both = wide.dropna(subset=[f"satisfied_{a}", f"satisfied_{b}"])
    if both["spec"].nunique() > 1:
        person = (
            both.assign(
                sat_diff=both[f"satisfied_{a}"].astype(float) - both[f"satisfied_{b}"].astype(float),
                trust_diff=both[f"trust_{a}"] - both[f"trust_{b}"],
            )
            .groupby("participant")[["sat_diff", "trust_diff"]]
            .mean()
        )
        sat = wilcoxon_paired(person["sat_diff"].to_numpy(), np.zeros(len(person)))
        trust = mean_difference(person["trust_diff"].to_numpy(), np.zeros(len(person)), rng, resamples)
        sat_mean = mean_difference(person["sat_diff"].to_numpy(), np.zeros(len(person)), rng, resamples)
        wx = wilcoxon_paired(person["trust_diff"].to_numpy(), np.zeros(len(person)))
        rows.append(
            {
                "spec": ALL_SPECS,
                "condition_a": a,
                "condition_b": b,
                "unit": "participant (mean over specs)",
                "pairs": int(len(person)),
                "mcnemar_p": None,
                "sign_test_p": sat.p_value,
                "risk_difference": _finite(sat_mean.value),
                "rd_low": _finite(sat_mean.low),
                "rd_high": _finite(sat_mean.high),
                "trust_difference": _finite(trust.value),
                "trust_diff_low": _finite(trust.low),
                "trust_diff_high": _finite(trust.high),
                "wilcoxon_pairs": wx.pairs,
                "wilcoxon_p": wx.p_value,
                "median_trust_difference": _finite(wx.median_difference),
            }
        )
    return pd.DataFrame(rows)


PER_TYPE_CELL_COLUMNS = (
    "spec", "condition", "n", "satisfied", "satisfaction_rate", "ci_low", "ci_high", "mean_trust",
    "trust_ci_low", "trust_ci_high", "mean_true_trust", "takeovers_per_episode",
)


def per_type_tables(
    episodes: pd.DataFrame, spec_order, condition_order, belief_source: str, rng: np.random.Generator,
    resamples: int,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per true driver type and over all participants: the cells (satisfaction with exact CI, mean
    reported trust with bootstrap CI, mean true trust) and the paired statistics of every pair of
    conditions (in config order). Empty without a `driver_type` in the episodes."""
    if "driver_type" not in episodes or not episodes["driver_type"].notna().any():
        return pd.DataFrame(), pd.DataFrame()
    names = sorted(episodes["driver_type"].dropna().unique())
    groups = [(name, episodes[episodes["driver_type"] == name]) for name in names]
    groups.append((ALL_TYPES, episodes))
    column = f"satisfied_{belief_source}"
    cells, paired = [], []
    for name, group in groups:
        table = cell_table(group, spec_order, condition_order, belief_source, {}, rng, resamples)
        cells.append(table[list(PER_TYPE_CELL_COLUMNS)].assign(
            driver_type=name, participants=group["participant"].nunique()))
        for pair in itertools.combinations(condition_order, 2):
            rows = paired_table_rows(per_participant_table(group, column, pair), pair, spec_order, rng,
                                     resamples)
            if len(rows):
                paired.append(rows.assign(driver_type=name))
    cell_frame = pd.concat(cells, ignore_index=True)
    cell_frame = cell_frame[["driver_type", "participants", *PER_TYPE_CELL_COLUMNS]]
    if not paired:
        return cell_frame, pd.DataFrame()
    paired_frame = pd.concat(paired, ignore_index=True)
    return cell_frame, paired_frame[["driver_type", *[c for c in paired_frame.columns if c != "driver_type"]]]


def repeated_measures_table(episodes: pd.DataFrame, column: str, pair: tuple[str, str]) -> pd.DataFrame:
    a, b = pair
    subset = episodes[episodes["condition"].isin(pair)]
    treated = (subset["condition"] == a).to_numpy(dtype=float)
    participant = subset["participant"].to_numpy()
    spec = subset["spec"].to_numpy()
    strata = spec if len(set(spec)) > 1 else None
    rows = []
    for outcome, effect in (
        (
            "satisfied (odds ratio)",
            conditional_logit(subset[column].to_numpy(dtype=float), treated, participant, strata),
        ),
        (
            "mean reported trust (difference)",
            mixed_trust_model(
                subset["mean_reported_trust"].to_numpy(dtype=float), treated, participant, strata
            ),
        ),
    ):
        rows.append(
            {
                "outcome": outcome,
                "model": effect.model,
                "effect_of": f"{a} vs {b}",
                "estimate": _finite(effect.estimate),
                "low": _finite(effect.low),
                "high": _finite(effect.high),
                "p_value": _finite(effect.p_value),
                "participants": effect.groups,
                "episodes": effect.observations,
                "note": effect.note,
            }
        )
    return pd.DataFrame(rows)


def takeover_table(roads: pd.DataFrame, episodes: pd.DataFrame, condition_order) -> pd.DataFrame:
    merged = roads[roads["index"] > 0][["episode_id", "incident", "takeover"]].merge(
        episodes[["episode_id", "condition"]], on="episode_id"
    )
    merged = merged[merged["incident"].fillna("").astype(str) != ""]
    rows = []
    for (incident, condition), group in merged.groupby(["incident", "condition"], sort=True):
        n, k = len(group), int(group["takeover"].sum())
        low, high = rate_interval(k, n)
        rows.append(
            {
                "incident": incident,
                "condition": condition,
                "roads": n,
                "takeovers": k,
                "rate": k / n,
                "ci_low": low,
                "ci_high": high,
            }
        )
    table = pd.DataFrame(
        rows, columns=["incident", "condition", "roads", "takeovers", "rate", "ci_low", "ci_high"]
    )
    if len(table):
        order = {c: i for i, c in enumerate(condition_order)}
        table = table.sort_values(
            ["incident", "condition"], key=lambda s: s.map(order) if s.name == "condition" else s
        ).reset_index(drop=True)
    return table


def order_tables(episodes: pd.DataFrame, column: str) -> tuple[pd.DataFrame, dict, pd.DataFrame]:
    """Position effects (per Latin-square position) and carry-over (by the previous condition)."""
    from scipy import stats
    from statsmodels.stats.contingency_tables import cochrans_q

    rows = []
    for position, group in episodes.groupby("position", sort=True):
        n, k = len(group), int(group[column].sum())
        low, high = rate_interval(k, n)
        rows.append(
            {
                "position": int(position) + 1,
                "n": n,
                "satisfied": k,
                "satisfaction_rate": k / n,
                "ci_low": low,
                "ci_high": high,
                "mean_trust": _finite(np.nanmean(group["mean_reported_trust"].to_numpy(dtype=float)))
                if group["mean_reported_trust"].notna().any()
                else None,
            }
        )
    order = pd.DataFrame(rows)
    tests: dict = {"cochran_q_p": None, "friedman_p": None, "participants": 0}
    positions = episodes["position"].nunique()
    complete = episodes.groupby("participant").filter(lambda g: g["position"].nunique() == positions)
    if positions >= 2 and complete["participant"].nunique() >= 2:
        sat = complete.pivot_table(index="participant", columns="position", values=column, aggfunc="first")
        trust = complete.pivot_table(
            index="participant", columns="position", values="mean_reported_trust", aggfunc="first"
        ).dropna()
        tests["participants"] = int(len(sat))
        if sat.to_numpy().std() > 0:
            tests["cochran_q_p"] = float(cochrans_q(sat.to_numpy(dtype=int)).pvalue)
        if positions >= 3 and len(trust) >= 2 and trust.to_numpy().std() > 0:
            tests["friedman_p"] = float(stats.friedmanchisquare(*trust.to_numpy().T).pvalue)
    ordered = episodes.sort_values(["participant", "position"])
    previous = ordered.groupby("participant")["condition"].shift(1).fillna("none (first)")
    carry = ordered.assign(previous=previous)
    rows = []
    for (condition, before), group in carry.groupby(["condition", "previous"], sort=True):
        n, k = len(group), int(group[column].sum())
        low, high = rate_interval(k, n)
        rows.append(
            {
                "condition": condition,
                "previous_condition": before,
                "n": n,
                "satisfaction_rate": k / n,
                "ci_low": low,
                "ci_high": high,
                "mean_trust": _finite(group["mean_reported_trust"].mean()),
            }
        )
    return order, tests, pd.DataFrame(rows)


def is_paper_comparable(manifest: dict, episodes: pd.DataFrame) -> tuple[bool, str]:
    """The paper's table applies to the paper's town, its φ1 and φ2 and 21 participants only."""
    from trustroute.core.packaged import PACKAGED_SPECS
    from trustroute.networks.town import load_town
    from trustroute.policies.logic.spec import load_spec

    config = manifest.get("config", {})
    reasons = []
    participants = config.get("participants")
    if participants != PAPER["participants"]:
        reasons.append(f"{participants} participants, the paper had {PAPER['participants']}")
    default_town = load_town(None)
    town = load_town(config.get("town")) if config.get("town") else default_town
    if town.content_hash != default_town.content_hash:
        reasons.append("another town")
    for name in ("phi1", "phi2"):
        ours = [p for p in config.get("specs", []) if Path(p).stem == name]
        if (
            not ours
            or load_spec(_spec_path(ours[0]), town).content_hash
            != load_spec(PACKAGED_SPECS / f"{name}.toml", town).content_hash
        ):
            reasons.append(f"not the paper's {name}")
    if not {"aware", "free"} <= set(episodes["condition"]):
        reasons.append("not the aware and free conditions")
    if reasons:
        return False, (
            "The paper's figures are not shown: this study is not comparable to it ("
            + "; ".join(reasons)
            + ")."
        )
    return True, ""


def study_analysis(study_dir: Path, belief_source: str = "filter", resamples: int = 10_000) -> StudyAnalysis:
    if belief_source not in BELIEF_SOURCES:
        raise InputError(
            "--belief-source",
            "",
            f"unknown belief source {belief_source!r}",
            f"use one of {', '.join(BELIEF_SOURCES)}",
        )
    manifest, episodes, roads = load_study(study_dir)
    town, driver, specs = study_inputs(manifest)
    satisfaction = episodes[["episode_id", "participant", "spec", "condition"]].copy()
    for source in BELIEF_SOURCES:
        result = episode_satisfaction(roads, episodes, specs, town, driver.trust_levels, source)
        mapped = dict(zip(result["episode_id"], result["satisfied"], strict=True))
        satisfaction[f"satisfied_{source}"] = (
            satisfaction["episode_id"].map(mapped).fillna(False).astype(bool)
        )
    episodes = episodes.merge(
        satisfaction[["episode_id", "satisfied_filter", "satisfied_reported"]], on="episode_id", how="left"
    )
    if "mean_reported_trust" in episodes:
        episodes["mean_reported_trust"] = pd.to_numeric(episodes["mean_reported_trust"], errors="coerce")
    expected = manifest.get("expected", {})
    rng = np.random.default_rng(ANALYSIS_SEED)
    spec_order = [Path(p).stem for p in manifest["config"]["specs"]]
    condition_order = list(dict.fromkeys(episodes["condition"])) if len(episodes) else []
    config_conditions = [
        c if c in ("aware", "free") else Path(c).stem for c in manifest["config"]["conditions"]
    ]
    condition_order = [c for c in config_conditions if c in condition_order] or condition_order
    column = f"satisfied_{belief_source}"

    cells = cell_table(episodes, spec_order, condition_order, belief_source, expected, rng, resamples)
    pair = _pair_conditions(condition_order)
    empty = pd.DataFrame()
    if pair is not None and len(episodes):
        wide = per_participant_table(episodes, column, pair)
        paired = paired_table_rows(wide, pair, spec_order, rng, resamples)
        repeated = repeated_measures_table(episodes, column, pair)
    else:
        wide, paired, repeated = empty, empty, empty
    takeovers = takeover_table(roads, episodes, condition_order)
    if len(episodes):
        order, order_tests, carryover = order_tables(episodes, column)
    else:
        order, order_tests, carryover = empty, {}, empty
    per_type, per_type_paired = per_type_tables(episodes, spec_order, condition_order, belief_source,
                                                rng, resamples)
    analysis = StudyAnalysis(
        study_dir=Path(study_dir),
        belief_source=belief_source,
        manifest=manifest,
        cells=cells,
        paired=paired,
        repeated=repeated,
        takeovers=takeovers,
        order=order,
        order_tests=order_tests,
        carryover=carryover,
        per_participant=wide,
        paper=pd.DataFrame(columns=["figure", "paper", "ours"]),
        paper_note="",
        satisfaction=satisfaction,
        episodes=episodes,
        per_type=per_type,
        per_type_paired=per_type_paired,
    )
    comparable, note = is_paper_comparable(manifest, episodes)
    if comparable:
        analysis.paper = pd.DataFrame(paper_comparison(analysis), columns=["figure", "paper", "ours"])
    analysis.paper_note = note
    return analysis


def paper_comparison(analysis: StudyAnalysis) -> list[dict]:
    """The paper's headline figures beside this study's (docs/study.md, "Headline figures of the paper")."""
    episodes, source = analysis.episodes, analysis.belief_source
    rows = []
    for spec, (k, n) in PAPER["satisfied_aware"].items():
        group = episodes[(episodes["spec"] == spec) & (episodes["condition"] == "aware")]
        ours = int(group[f"satisfied_{source}"].sum())
        low, high = rate_interval(ours, len(group))
        rows.append(
            {
                "figure": f"participants satisfying {spec} (aware)",
                "paper": f"{k}/{n}",
                "ours": f"{ours}/{len(group)} (exact 95% CI [{low:.3f}, {high:.3f}])",
            }
        )

    def by_condition(column: str, digits: int) -> str:
        values = []
        for condition in ("aware", "free"):
            group = episodes[episodes["condition"] == condition]
            values.append(f"{group[column].mean():.{digits}f}" if len(group) else "not run")
        return " vs ".join(values)

    rows.append(
        {
            "figure": "satisfaction aware vs free",
            "paper": "0.85 vs 0.775",
            "ours": by_condition(f"satisfied_{source}", 3),
        }
    )
    rows.append(
        {
            "figure": "average trust aware vs free (reported)",
            "paper": "4.6018 vs 4.3933",
            "ours": by_condition("mean_reported_trust", 4),
        }
    )
    cells = analysis.cells.set_index(["spec", "condition"]) if len(analysis.cells) else None
    for spec, value in PAPER["pr_max"].items():
        ours = "not available"
        within = ""
        if cells is not None and (spec, "aware") in cells.index:
            cell = cells.loc[(spec, "aware")]
            lower, upper = cell["synthesized_lower"], cell["synthesized_upper"]
            if lower is not None and upper is not None and not pd.isna(lower) and not pd.isna(upper):
                ours = f"[{lower:.4f}, {upper:.4f}]"
            if cell["synthesized_horizon"] is not None and not pd.isna(cell["synthesized_horizon"]):
                within = f", ours within H={int(cell['synthesized_horizon'])} junctions"
        rows.append({"figure": f"Pr_max({spec}), synthesized{within}", "paper": f"{value}", "ours": ours})
    return rows


# -- display ----------------------------------------------------------------------------------------


def _num(value: object, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)) or value is pd.NA:
        return "-"
    if isinstance(value, (float, np.floating)):
        return "inf" if math.isinf(value) else f"{value:.{digits}f}"
    return str(value)


def _interval(low: object, high: object, digits: int = 3) -> str:
    if _num(low) == "-" or _num(high) == "-":
        return "-"
    return f"[{_num(low, digits)}, {_num(high, digits)}]"


def _intervals(frame: pd.DataFrame, low: str, high: str, digits: int = 3) -> list[str]:
    """The column pair (low, high) of a table as formatted intervals."""
    return [_interval(a, b, digits) for a, b in zip(frame[low], frame[high], strict=True)]


def _estimates(frame: pd.DataFrame, value: str, low: str, high: str, digits: int = 3) -> list[str]:
    """'estimate [low, high]' per row; '-' where the estimate is missing (or the column absent)."""
    missing = [None] * len(frame)
    return [
        f"{_num(v, digits)} {_interval(lo, hi, digits)}" if _num(v) != "-" else "-"
        for v, lo, hi in zip(frame.get(value, missing), frame.get(low, missing),
                             frame.get(high, missing), strict=True)
    ]


def paired_display(p: pd.DataFrame) -> pd.DataFrame:
    """Paired statistics as shown (one row per spec and pair; a driver type first when given)."""
    shown = pd.DataFrame(
        {
            "spec": p["spec"],
            "pair": p["condition_a"] + " vs " + p["condition_b"],
            "unit": p["unit"],
            "n": p["pairs"],
            "only A / only B sat.": [
                f"{int(a)} / {int(b)}" if _num(a) != "-" else "-"
                for a, b in zip(
                    p.get("only_a_satisfied", [None] * len(p)),
                    p.get("only_b_satisfied", [None] * len(p)),
                    strict=True,
                )
            ],
            "risk difference [95% CI]": _estimates(p, "risk_difference", "rd_low", "rd_high"),
            "conditional OR [exact CI]": _estimates(p, "odds_ratio", "or_low", "or_high", 2),
            "McNemar exact p": [format_p(_finite(v)) for v in p["mcnemar_p"]],
            "trust difference [BCa CI]": _estimates(
                p, "trust_difference", "trust_diff_low", "trust_diff_high"
            ),
            "Wilcoxon p (trust)": [format_p(_finite(v)) for v in p["wilcoxon_p"]],
        }
    )
    if "driver_type" in p:
        shown.insert(0, "driver type", p["driver_type"].to_numpy())
    return shown


def _outcome_columns(cells: pd.DataFrame) -> dict[str, pd.Series]:
    """Satisfied count, rate and exact interval, as every per-cell display table shows them."""
    return {"satisfied": cells["satisfied"], "rate": cells["satisfaction_rate"].map(_num),
            "exact 95% CI": _intervals(cells, "ci_low", "ci_high")}


def _trust_columns(cells: pd.DataFrame) -> dict[str, pd.Series]:
    """Reported and true trust and takeovers, as every per-cell display table shows them."""
    return {"mean trust (reported)": cells["mean_trust"].map(_num),
            "trust 95% CI": _intervals(cells, "trust_ci_low", "trust_ci_high", 2),
            "mean true trust": cells["mean_true_trust"].map(_num),
            "takeovers / episode": cells["takeovers_per_episode"].map(lambda v: _num(v, 2))}


def display_tables(analysis: StudyAnalysis) -> dict[str, pd.DataFrame]:
    """The tables as shown (formatted strings, p-values in scientific notation), by name."""
    other = [s for s in BELIEF_SOURCES if s != analysis.belief_source][0]
    tables: dict[str, pd.DataFrame] = {}
    c = analysis.cells
    if len(c):
        tables["cells"] = pd.DataFrame(
            {
                "spec": c["spec"],
                "condition": c["condition"],
                "n": c["n"],
                **_outcome_columns(c),
                "Wilson 95% CI": _intervals(c, "wilson_low", "wilson_high"),
                f"rate ({other})": c[f"satisfaction_rate_{other}"].map(_num),
                "exact value [L, U]": _intervals(c, "exact_lower", "exact_upper"),
                "synthesized [L, U]": _intervals(c, "synthesized_lower", "synthesized_upper"),
                **_trust_columns(c),
                "junctions": c["mean_junctions"].map(lambda v: _num(v, 1)),
                "fallback": c["fallback_rate"].map(lambda v: _num(v, 2)),
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
                "estimate [95% CI]": _estimates(r, "estimate", "low", "high"),
                "p": [format_p(_finite(v)) for v in r["p_value"]],
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
                "rate": t["rate"].map(_num),
                "exact 95% CI": _intervals(t, "ci_low", "ci_high"),
            }
        )
    o = analysis.order
    if len(o):
        tables["order"] = pd.DataFrame(
            {
                "position": o["position"],
                "n": o["n"],
                "rate": o["satisfaction_rate"].map(_num),
                "exact 95% CI": _intervals(o, "ci_low", "ci_high"),
                "mean trust (reported)": o["mean_trust"].map(_num),
            }
        )
    k = analysis.carryover
    if len(k):
        tables["carryover"] = pd.DataFrame(
            {
                "condition": k["condition"],
                "driven after": k["previous_condition"],
                "n": k["n"],
                "rate": k["satisfaction_rate"].map(_num),
                "exact 95% CI": _intervals(k, "ci_low", "ci_high"),
                "mean trust (reported)": k["mean_trust"].map(_num),
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


def format_table(analysis: StudyAnalysis) -> str:
    """Plain-text tables for the terminal."""
    lines = [
        f"study {analysis.manifest.get('study')} ({analysis.manifest.get('engine')} engine); "
        f"satisfaction on beliefs from: {analysis.belief_source}"
    ]
    for name, table in display_tables(analysis).items():
        lines += ["", TABLE_TITLES[name], table.to_string(index=False)]
    if analysis.order_tests:
        lines.append(order_test_line(analysis.order_tests))
    if analysis.paper_note:
        lines += ["", analysis.paper_note]
    return "\n".join(lines)


def order_test_line(tests: dict) -> str:
    return (
        f"Across positions within {tests.get('participants', 0)} participants: Cochran's Q p = "
        f"{format_p(tests.get('cochran_q_p'))} (satisfaction), Friedman p = "
        f"{format_p(tests.get('friedman_p'))} (reported trust)."
    )
