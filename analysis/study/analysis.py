"""The analysis of one study directory, shared by `trustroute analyze`, the report and fitting.

`study_analysis(study_dir, belief_source)` reads a consolidated study directory (episodes.parquet,
roads.parquet, manifest.json), evaluates the specs on the logs, and returns a `StudyAnalysis` whose
tables (pandas DataFrames, built by the modules beside this one: cells, paired, order, per_type,
paper_comparison; shown by display) are:

- `cells`: per (spec, condition): n, satisfied, the satisfaction rate with its exact
  (Clopper–Pearson) and Wilson 95 % intervals on the chosen belief source (and the rate on the
  other source), mean reported trust with a bootstrap CI, mean true and final trust, junctions,
  takeovers, fallback rate, the policy's exact value and its synthesized [lower, upper];
- `paired`: per spec, every pair of conditions (paired.py `condition_pairs`: "aware" first, "free"
  last) over participants, each p-value with its Holm-adjusted value over the pairs: the 2x2
  counts, exact McNemar p, the risk difference (Newcombe interval), the conditional odds ratio
  (exact interval), the mean difference in reported trust (BCa bootstrap over participants),
  Wilcoxon p. The "all specs" row is per participant, not per pair: each participant's satisfaction
  under A minus under B averaged over specs (the risk difference is the mean of these, with a BCa
  interval; the sign test counts their signs), and their trust difference averaged over specs, so
  21 participants count as 21, never as 42 pairs;
- `repeated`: models over every episode with one group per participant: conditional logistic
  regression of satisfaction on the condition with spec fixed effects, and a mixed model of mean
  reported trust with a random intercept per participant (REML, repeated_measures.py);
- `takeovers`: per incident type and condition, roads met, takeovers, rate with exact interval;
- `order`: per position in the Latin square: satisfaction (exact interval) and mean trust, with
  Cochran's Q (satisfaction) and Friedman (trust) across positions within participants;
  `carryover`: per condition and the condition driven just before (same spec or not);
- `per_participant`: one row per participant and spec, the outcomes under each condition;
- `per_type` and `per_type_paired` (studies with a `[drivers] population`, whose episodes carry the
  participant's true `driver_type`): the cells' satisfaction and trust, and the paired statistics
  for every pair of conditions present (free, aware, robust, policy files), per true type and over
  all participants ("all");
- `manual`: per incident type and condition, the manual-driving measures of the takeovers
  (manual.py; the incidents table's, docs/dataset.md); empty without takeovers;
- `sensitivity`: every pair's satisfaction difference per spec and over specs on every belief
  source the study has (sensitivity.py), the leading one marked;
- `paper`: the paper's figures beside ours, only when the study is comparable (the paper's town,
  its φ1 and φ2, 21 participants); otherwise `paper_note` says why not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.belief_sources import (
    BELIEF_SOURCES,
    SIMULATED_ENGINES,
    SourceUnavailable,
    declared_belief_source,
    default_belief_source,
    refiltered,
    source_label,
    true_roads,
)
from trustroute.analysis.satisfaction import episode_satisfaction
from trustroute.analysis.study.canonical import canonical_tables, in_rank_order
from trustroute.analysis.study.cells import cell_table, takeover_table
from trustroute.analysis.study.manual import manual_table, study_incidents
from trustroute.analysis.study.order import order_tables, run_order
from trustroute.analysis.study.paired import (
    all_pairs_repeated,
    all_pairs_table,
    condition_pairs,
    per_participant_table,
)
from trustroute.analysis.study.paper_comparison import is_paper_comparable, paper_comparison
from trustroute.analysis.study.per_type import per_type_tables
from trustroute.analysis.study.questionnaires import questionnaire_tables
from trustroute.analysis.study.sensitivity import sensitivity_table
from trustroute.analysis.study_directory import LoadedStudy, load_study, study_inputs
from trustroute.core.errors import InputError
from trustroute.core.wording import shown_value
from trustroute.harness.study.context import reference_model

# bootstrap resampling: fixed, so an analysis is reproducible; each bootstrap draws from a Generator
# keyed by what it resamples (statistics.py `keyed_rng`)
ANALYSIS_SEED = 20240513
MULTIPLICITY = ("Holm over every pair of conditions, per spec and test (per outcome for the models; per "
                "driver type and spec for the per-type tables; per questionnaire for the questionnaire "
                "tests); columns *_holm")


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
    questionnaires: pd.DataFrame = field(default_factory=pd.DataFrame)        # live: scores, alpha
    questionnaire_tests: pd.DataFrame = field(default_factory=pd.DataFrame)   # live: paired tests
    sensitivity: pd.DataFrame = field(default_factory=pd.DataFrame)
    manual: pd.DataFrame = field(default_factory=pd.DataFrame)
    source_note: str = ""   # why the leading source is not the default one, or a source is missing

    def to_dict(self) -> dict:
        return {
            "study_dir": str(self.study_dir),
            "study": self.manifest.get("study"),
            "engine": self.manifest.get("engine"),
            "belief_source": self.belief_source,
            "belief_source_label": source_label(self.belief_source),
            "belief_source_note": self.source_note,
            "multiplicity": MULTIPLICITY,
            "cells": json_records(self.cells),
            "paired": json_records(self.paired),
            "repeated_measures": json_records(self.repeated),
            "takeovers": json_records(self.takeovers),
            "order": json_records(self.order),
            "order_tests": self.order_tests,
            "carryover": json_records(self.carryover),
            "paper_comparison": json_records(self.paper),
            "paper_note": self.paper_note,
            "per_type": json_records(self.per_type),
            "per_type_paired": json_records(self.per_type_paired),
            "questionnaires": json_records(self.questionnaires),
            "questionnaire_tests": json_records(self.questionnaire_tests),
            "sensitivity": json_records(self.sensitivity),
            "manual_driving": json_records(self.manual),
            "failed_episodes": len(self.manifest.get("failed_episodes", [])),
        }


def json_value(value: object) -> object:
    """One table value as JSON: a float at full precision (json writes its repr, the shortest text
    that reads back as the same float), null when missing or infinite, numpy scalars as Python's."""
    if value is None or value is pd.NA or value is pd.NaT:
        return None
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): json_value(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [json_value(v) for v in value]
    return value if isinstance(value, str) else str(value)


def json_records(frame: pd.DataFrame) -> list[dict]:
    """The rows of `frame` as JSON objects, every float at full precision: pandas' to_json rounds to
    10 decimal places, which writes a p-value of 2e-11 as 0."""
    return [{str(k): json_value(v) for k, v in row.items()} for row in frame.to_dict("records")]


def source_satisfaction(study_dir: Path, manifest: dict, episodes: pd.DataFrame,
                        roads: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, str]]:
    """(per episode: satisfied_<source> for every belief source the study has, {a source the study
    has not: what it needs}): "true" only for simulated studies whose drivers can be rebuilt (from
    their config; in a package, only when no driver's model depends on their number)."""
    town, driver, specs = study_inputs(manifest, study_dir)
    satisfaction = episodes[["episode_id", "participant", "spec", "condition"]].copy()
    reference = reference_model(manifest.get("config") or {}, driver)
    variants = {"filter": (roads, "filter"), "reported": (roads, "reported"),
                "reference": (refiltered(roads, reference, town), "filter")}
    missing = {}
    if manifest.get("engine") in SIMULATED_ENGINES:   # a person (live, imported logs) has no model
        try:
            variants["true"] = (true_roads(study_dir, manifest, roads, episodes, driver, town), "filter")
        except SourceUnavailable as error:   # no "true" source: the note and asking for it say why
            missing["true"] = error.needs
    else:
        missing["true"] = (f"a simulated study (this one is {manifest.get('engine')}: its drivers are "
                           "people, no model)")
    for source, (variant, evaluated) in variants.items():
        result = episode_satisfaction(variant, episodes, specs, town, driver.trust_levels, evaluated)
        mapped = dict(zip(result["episode_id"], result["satisfied"], strict=True))
        satisfaction[f"satisfied_{source}"] = (
            satisfaction["episode_id"].map(mapped).fillna(False).astype(bool)
        )
    return satisfaction, missing


def study_analysis(study_dir: Path, belief_source: str | None = None, resamples: int = 10_000,
                   loaded: LoadedStudy | None = None) -> StudyAnalysis:
    """The analysis of `study_dir` on `belief_source` (default: `default_belief_source`, common to
    every condition). `loaded`: the study as `load_study(study_dir, package=True)` read it, so
    that a command analysing it on several sources reads and checks it once."""
    manifest, episodes, roads = load_study(study_dir, package=True) if loaded is None else loaded
    chosen = belief_source is not None or declared_belief_source(manifest) is not None
    belief_source = default_belief_source(manifest) if belief_source is None else belief_source
    if belief_source not in BELIEF_SOURCES:
        raise InputError(
            "--belief-source",
            "",
            f"unknown belief source {shown_value(belief_source)}",
            f"use one of {', '.join(BELIEF_SOURCES)}",
        )
    satisfaction, missing = source_satisfaction(Path(study_dir), manifest, episodes, roads)
    # from here on the participants' numbers are their ranks by content (canonical.py): the
    # "true" source above needed their own numbers, which give each one's driver model
    episodes, roads, rank_of_episode, (satisfaction,) = canonical_tables(episodes, roads, satisfaction)
    source_note = ""
    if f"satisfied_{belief_source}" not in satisfaction and not chosen:
        # a simulated study whose drivers cannot be rebuilt: the reports are the neutral source left
        source_note = (f"the default source {belief_source!r} needs {missing[belief_source]}: 'reported' "
                       "leads instead")
        belief_source = "reported"
    elif manifest.get("engine") in SIMULATED_ENGINES and "true" in missing:   # said, not dropped
        source_note = f"the source 'true' is not available: it needs {missing['true']}"
    if f"satisfied_{belief_source}" not in satisfaction:
        raise InputError("--belief-source", "", f"belief source {belief_source!r} needs "
                         f"{missing[belief_source]}", "use filter, reported or reference")
    episodes = episodes.merge(
        satisfaction[["episode_id", *[c for c in satisfaction if c.startswith("satisfied_")]]],
        on="episode_id", how="left"
    )
    if "mean_reported_trust" in episodes:
        episodes["mean_reported_trust"] = pd.to_numeric(episodes["mean_reported_trust"], errors="coerce")
    expected = manifest.get("expected", {})
    spec_order = [Path(p).stem for p in manifest["config"]["specs"]]
    condition_order = list(dict.fromkeys(episodes["condition"])) if len(episodes) else []
    config_conditions = [
        c if c in ("aware", "free") else Path(c).stem for c in manifest["config"]["conditions"]
    ]
    condition_order = [c for c in config_conditions if c in condition_order] or condition_order
    column = f"satisfied_{belief_source}"

    cells = cell_table(episodes, spec_order, condition_order, belief_source, expected, ANALYSIS_SEED,
                       resamples)
    pairs = condition_pairs(condition_order)
    empty = pd.DataFrame()
    if pairs and len(episodes):
        wide = per_participant_table(episodes, column, tuple(condition_order))
        paired = all_pairs_table(wide, pairs, spec_order, ANALYSIS_SEED, resamples)
        repeated = all_pairs_repeated(episodes, column, pairs)
    else:
        wide, paired, repeated = empty, empty, empty
    takeovers = takeover_table(roads, episodes, condition_order)
    if len(episodes):
        order, order_tests, carryover = order_tables(run_order(Path(study_dir), manifest, episodes), column)
    else:
        order, order_tests, carryover = empty, {}, empty
    per_type, per_type_paired = per_type_tables(episodes, spec_order, condition_order, belief_source,
                                                ANALYSIS_SEED, resamples)
    sources = [s for s in BELIEF_SOURCES if f"satisfied_{s}" in episodes]
    sensitivity = sensitivity_table(episodes, sources, belief_source, paired, condition_order, spec_order,
                                    ANALYSIS_SEED, resamples)
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
        sensitivity=sensitivity,
        manual=manual_table(in_rank_order(study_incidents(Path(study_dir)), rank_of_episode), episodes,
                            condition_order),
        source_note=source_note,
    )
    questionnaires = questionnaire_tables(Path(study_dir), episodes, pairs)
    analysis.questionnaires, analysis.questionnaire_tests = questionnaires
    comparable, note = is_paper_comparable(manifest, episodes)
    if comparable:
        analysis.paper = pd.DataFrame(paper_comparison(episodes, cells, belief_source),
                                      columns=["figure", "paper", "ours"])
    analysis.paper_note = note
    return analysis
