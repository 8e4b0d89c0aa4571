"""Per-study tables: satisfaction and trust per spec and condition, paired tests, the paper beside us.

`study_analysis(study_dir, belief_source)` reads a consolidated study directory (episodes.parquet,
roads.parquet, manifest.json) and returns a `StudyAnalysis`:

- one cell per (spec, condition): n, satisfied, satisfaction_rate with a bootstrap CI on the
  chosen belief source (and the rate on the other source beside it), mean_trust = the mean over
  episodes of the episode's mean *reported* trust (what the paper's participants gave) with a
  bootstrap CI, the mean true trust and final trust, junctions, takeovers, fallback rate, and
  the policy's exact value (policies.evaluate, nominal driver) and synthesized [lower, upper];
- per spec, a paired comparison of the first two conditions ("aware" vs "free" when present) over
  participants: exact McNemar on satisfaction, Wilcoxon signed-rank on mean reported trust;
- the paper's figures beside ours.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.dataset import read_episodes, read_manifest, read_roads
from trustroute.analysis.satisfaction import BELIEF_SOURCES, episode_satisfaction
from trustroute.analysis.statistics import bootstrap_ci, mcnemar_exact, wilcoxon_paired
from trustroute.networks.errors import InputError

PAPER = {
    "satisfied_aware": {"phi1": (18, 21), "phi2": (17, 21)},
    "satisfaction_rate": {"aware": 0.85, "free": 0.775},
    "mean_trust": {"aware": 4.6018, "free": 4.3933},
    "pr_max": {"phi1": 0.8357, "phi2": 0.7288},
}
ANALYSIS_SEED = 20240513  # bootstrap resampling: fixed, so an analysis is reproducible


@dataclass
class StudyAnalysis:
    study_dir: Path
    belief_source: str
    manifest: dict
    cells: list[dict]
    paired: list[dict]
    paper: list[dict]
    satisfaction: pd.DataFrame = field(repr=False)  # per episode, both sources
    episodes: pd.DataFrame = field(repr=False)

    def to_dict(self) -> dict:
        return {
            "study_dir": str(self.study_dir),
            "study": self.manifest.get("study"),
            "engine": self.manifest.get("engine"),
            "belief_source": self.belief_source,
            "cells": self.cells,
            "paired": self.paired,
            "paper_comparison": self.paper,
            "failed_episodes": len(self.manifest.get("failed_episodes", [])),
        }


def _finite(value: float) -> float | None:
    # pd.NA: the mean of a nullable column with no values (e.g. final_trust of real participants)
    if value is None or value is pd.NA or (isinstance(value, float) and math.isnan(value)):
        return None
    return float(value)


def load_study(study_dir: Path) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """(manifest, episodes, roads) of a consolidated study, read through trustroute.analysis.dataset."""
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
    from trustroute.harness.study.config import PACKAGED_SPECS

    recorded = Path(path)
    packaged = PACKAGED_SPECS / recorded.name
    return recorded if recorded.exists() or not packaged.exists() else packaged


def _pair_conditions(conditions: list[str]) -> tuple[str, str] | None:
    if "aware" in conditions and "free" in conditions:
        return "aware", "free"
    return (conditions[0], conditions[1]) if len(conditions) >= 2 else None


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
    other = [s for s in BELIEF_SOURCES if s != belief_source][0]
    expected = manifest.get("expected", {})
    rng = np.random.default_rng(ANALYSIS_SEED)
    spec_order = [Path(p).stem for p in manifest["config"]["specs"]]
    condition_order = list(dict.fromkeys(episodes["condition"])) if len(episodes) else []
    config_conditions = [
        c if c in ("aware", "free") else Path(c).stem for c in manifest["config"]["conditions"]
    ]
    condition_order = [c for c in config_conditions if c in condition_order] or condition_order

    cells = []
    for spec in spec_order:
        for condition in condition_order:
            group = episodes[(episodes["spec"] == spec) & (episodes["condition"] == condition)]
            sat = group[f"satisfied_{belief_source}"].to_numpy(dtype=float)
            trust = group["mean_reported_trust"].to_numpy(dtype=float)
            low, high = bootstrap_ci(sat, rng, resamples)
            trust_low, trust_high = bootstrap_ci(trust, rng, resamples)
            exp = expected.get(spec, {}).get(condition, {})
            cells.append(
                {
                    "spec": spec,
                    "condition": condition,
                    "n": int(len(group)),
                    "satisfied": int(sat.sum()),
                    "satisfaction_rate": _finite(sat.mean()) if len(group) else None,
                    "ci_low": _finite(low),
                    "ci_high": _finite(high),
                    f"satisfaction_rate_{other}": _finite(group[f"satisfied_{other}"].mean())
                    if len(group)
                    else None,
                    "logged_satisfaction_rate": _finite(group["satisfied"].mean()) if len(group) else None,
                    "mean_trust": _finite(np.nanmean(trust)) if np.isfinite(trust).any() else None,
                    "trust_ci_low": _finite(trust_low),
                    "trust_ci_high": _finite(trust_high),
                    "mean_true_trust": _finite(group["mean_trust"].mean()) if len(group) else None,
                    "mean_final_trust": _finite(group["final_trust"].mean()) if len(group) else None,
                    "mean_junctions": _finite(group["junctions"].mean()) if len(group) else None,
                    "takeovers_per_episode": _finite(group["takeovers"].mean()) if len(group) else None,
                    "fallback_rate": _finite(group["fallback_fired"].mean()) if len(group) else None,
                    "exact_lower": exp.get("exact_lower"),
                    "exact_upper": exp.get("exact_upper"),
                    "exact_final_trust": exp.get("expected_final_trust"),
                    "synthesized_lower": exp.get("synthesized_lower"),
                    "synthesized_upper": exp.get("synthesized_upper"),
                    "synthesized_horizon": exp.get("synthesized_horizon"),
                }
            )

    paired = []
    pair = _pair_conditions(condition_order)
    if pair is not None:
        a, b = pair
        for spec in [*spec_order, "all"]:
            subset = episodes if spec == "all" else episodes[episodes["spec"] == spec]
            wide = subset.pivot_table(
                index=["participant", "spec"],
                columns="condition",
                values=[f"satisfied_{belief_source}", "mean_reported_trust"],
                aggfunc="first",
            )
            column = f"satisfied_{belief_source}"
            if (column, a) not in wide or (column, b) not in wide:
                continue
            both = wide[[(column, a), (column, b)]].dropna()
            mc = mcnemar_exact(both[(column, a)].astype(bool), both[(column, b)].astype(bool))
            trust_a = wide[("mean_reported_trust", a)].to_numpy(dtype=float)
            trust_b = wide[("mean_reported_trust", b)].to_numpy(dtype=float)
            wx = wilcoxon_paired(trust_a, trust_b)
            paired.append(
                {
                    "spec": spec,
                    "condition_a": a,
                    "condition_b": b,
                    "pairs": mc.pairs,
                    "only_a_satisfied": mc.only_first,
                    "only_b_satisfied": mc.only_second,
                    "mcnemar_p": mc.p_value,
                    "wilcoxon_pairs": wx.pairs,
                    "wilcoxon_statistic": _finite(wx.statistic),
                    "wilcoxon_p": wx.p_value,
                    "median_trust_difference": _finite(wx.median_difference),
                }
            )
    analysis = StudyAnalysis(
        study_dir=Path(study_dir),
        belief_source=belief_source,
        manifest=manifest,
        cells=cells,
        paired=paired,
        paper=[],
        satisfaction=satisfaction,
        episodes=episodes,
    )
    analysis.paper = paper_comparison(analysis)
    return analysis


def paper_comparison(analysis: StudyAnalysis) -> list[dict]:
    """The paper's headline figures beside this study's (DESIGN.md, "Headline figures")."""
    episodes, source = analysis.episodes, analysis.belief_source
    names = list(dict.fromkeys(episodes["spec"])) if len(episodes) else []

    def ours_for(paper_spec: str) -> str | None:
        """This study's spec for the paper's: the same name, else a variant ("phi1_strict")."""
        for name in names:
            if name == paper_spec:
                return name
        return next((name for name in names if name.startswith(f"{paper_spec}_")), None)

    rows = []
    for paper_spec, (k, n) in PAPER["satisfied_aware"].items():
        spec = ours_for(paper_spec)
        group = episodes[(episodes["spec"] == spec) & (episodes["condition"] == "aware")]
        ours = f"{int(group[f'satisfied_{source}'].sum())}/{len(group)}" if len(group) else "not run"
        label = paper_spec if spec in (None, paper_spec) else f"{paper_spec} (ours: {spec})"
        rows.append({"figure": f"participants satisfying {label} (aware)", "paper": f"{k}/{n}", "ours": ours})

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
    cells = {(c["spec"], c["condition"]): c for c in analysis.cells}
    for paper_spec, value in PAPER["pr_max"].items():
        spec = ours_for(paper_spec)
        cell = cells.get((spec, "aware"), {})
        lower, upper = cell.get("synthesized_lower"), cell.get("synthesized_upper")
        ours = f"[{lower:.4f}, {upper:.4f}]" if lower is not None and upper is not None else "not available"
        label = paper_spec if spec in (None, paper_spec) else f"{paper_spec} (ours: {spec})"
        horizon = cell.get("synthesized_horizon")
        within = f", ours within H={horizon} junctions" if horizon else ""
        rows.append({"figure": f"Pr_max({label}), synthesized{within}", "paper": f"{value}", "ours": ours})
    return rows


def _fmt(value: object, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def cell_rows(analysis: StudyAnalysis) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the main table (for the terminal and the report)."""
    other = [s for s in BELIEF_SOURCES if s != analysis.belief_source][0]
    header = [
        "spec",
        "condition",
        "n",
        "satisfied",
        "rate",
        "95% CI",
        f"rate ({other})",
        "exact [L, U]",
        "synthesized [L, U]",
        "mean trust (reported)",
        "trust 95% CI",
        "mean true trust",
        "junctions",
        "fallback",
    ]
    rows = []
    for c in analysis.cells:
        exact = f"[{c['exact_lower']:.3f}, {c['exact_upper']:.3f}]" if c["exact_lower"] is not None else "-"
        synth = (
            f"[{c['synthesized_lower']:.3f}, {c['synthesized_upper']:.3f}]"
            if c["synthesized_lower"] is not None
            else "-"
        )
        rows.append(
            [
                c["spec"],
                c["condition"],
                str(c["n"]),
                str(c["satisfied"]),
                _fmt(c["satisfaction_rate"]),
                f"[{_fmt(c['ci_low'])}, {_fmt(c['ci_high'])}]",
                _fmt(c[f"satisfaction_rate_{other}"]),
                exact,
                synth,
                _fmt(c["mean_trust"], 3),
                f"[{_fmt(c['trust_ci_low'], 2)}, {_fmt(c['trust_ci_high'], 2)}]",
                _fmt(c["mean_true_trust"], 3),
                _fmt(c["mean_junctions"], 1),
                _fmt(c["fallback_rate"], 2),
            ]
        )
    return header, rows


def format_table(analysis: StudyAnalysis) -> str:
    """Plain-text tables for the terminal."""
    header, rows = cell_rows(analysis)
    lines = [
        f"study {analysis.manifest.get('study')} ({analysis.manifest.get('engine')} engine); "
        f"satisfaction on beliefs from: {analysis.belief_source}"
    ]
    lines += _aligned(header, rows)
    if analysis.paired:
        lines.append("")
        lines += _aligned(
            [
                "spec",
                "pair",
                "pairs",
                "only A sat.",
                "only B sat.",
                "McNemar p",
                "Wilcoxon p",
                "median trust diff",
            ],
            [
                [
                    p["spec"],
                    f"{p['condition_a']} vs {p['condition_b']}",
                    str(p["pairs"]),
                    str(p["only_a_satisfied"]),
                    str(p["only_b_satisfied"]),
                    f"{p['mcnemar_p']:.4f}",
                    f"{p['wilcoxon_p']:.4f}",
                    _fmt(p["median_trust_difference"], 3),
                ]
                for p in analysis.paired
            ],
        )
    lines.append("")
    lines += _aligned(
        ["figure", "paper", "ours"], [[r["figure"], r["paper"], r["ours"]] for r in analysis.paper]
    )
    return "\n".join(lines)


def _aligned(header: list[str], rows: list[list[str]]) -> list[str]:
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows, strict=True)]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    return [fmt.format(*header), fmt.format(*("-" * w for w in widths))] + [fmt.format(*r) for r in rows]
