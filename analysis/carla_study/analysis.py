"""The real CARLA study: satisfaction under three belief sources, the authors' statistics rule,
and the paper's figures beside ours, computed from an imported study directory.

Belief sources (docs/real_study.md, "Belief sources"):
- "logged": the belief the AV logged on each road (their policy's grid-projected update; in the
  free condition their simulator never updated it, so it stays the uniform prior);
- "reported": a point mass on the trust the participant displayed on arrival at each road;
- "bayes": the exact Bayes filter of the packaged driver model, run at import on the observed
  incidents and takeovers (the roads table's belief_after).

The authors' rule (`authors_point_rule`) re-implements statistic_test/statistic_test_point_based.py:
per log file, over the ticks with the autopilot on, the fraction with displayed trust >= 2; the
file "satisfies LDTL" when that fraction is >= 0.99; average trust is the mean displayed trust over
those ticks; takeover probability is the fraction of ticks with the autopilot off.
"""

from __future__ import annotations

import html
import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis import paper_figures
from trustroute.analysis.carla_study.log_schema import read_real_table
from trustroute.analysis.formatting import (
    MISSING,
    TERMINAL_WIDTH,
    finite_or_none,
    number_text,
    terminal_table,
    wrapped_text,
)
from trustroute.analysis.satisfaction import (
    LOGGED_BELIEF_SOURCES,
    REPORTED_TRUST_LABEL,
    satisfaction_by_source,
)
from trustroute.analysis.study_directory import LoadedStudy, load_study, study_inputs
from trustroute.core.dataset import REPORT_HTML_FILE, REPORT_MARKDOWN_FILE
from trustroute.core.wording import counted
from trustroute.policies.belief.problem import reads_hidden_trust

AUTHORS_SATISFIED_FRACTION = 0.99  # statistic_test_point_based.py: precetage >= 0.99
AUTHORS_LOW_TRUST = 2  # ... data.iloc[k, 1] >= 2 counts as satisfying


def authors_point_rule(ticks: pd.DataFrame) -> pd.DataFrame:
    """Per episode: the authors' point-based statistics from the run-length tick table."""
    t = ticks.assign(n=ticks["rows"])
    auto = t[t["autopilot"]]
    grouped = pd.DataFrame(
        {
            "autopilot_ticks": auto.groupby("episode_id")["n"].sum(),
            "trust_sum": (auto["n"] * auto["trust"]).groupby(auto["episode_id"]).sum(),
            "satisfying_ticks": auto[auto["trust"] >= AUTHORS_LOW_TRUST].groupby("episode_id")["n"].sum(),
            "all_ticks": t.groupby("episode_id")["n"].sum(),
        }
    ).fillna(0)
    grouped["fraction_trust_at_least_2"] = grouped["satisfying_ticks"] / grouped["autopilot_ticks"]
    grouped["authors_satisfied"] = grouped["fraction_trust_at_least_2"] >= AUTHORS_SATISFIED_FRACTION
    grouped["authors_average_trust"] = grouped["trust_sum"] / grouped["autopilot_ticks"]
    grouped["authors_takeover_probability"] = (grouped["all_ticks"] - grouped["autopilot_ticks"]) / grouped[
        "all_ticks"
    ]
    return grouped.reset_index()


def authors_segment_rule(ticks: pd.DataFrame) -> pd.DataFrame:
    """Per episode: statistic_test_segment_based.py's "average segment trust for complete path".

    Their loop starts at the file's second row (row 1 opens segment 0 whatever its autopilot
    flag); later rows count only with the autopilot on; a row on a different CARLA road id than the
    open segment opens a new one; the last (still open) segment is dropped from the average."""
    rows = []
    for episode_id, runs in ticks.groupby("episode_id", sort=False):
        sums: list[float] = []
        counts: list[int] = []
        entry: list[float] = []  # their "intersection trust": the row before a segment opens
        current = None
        previous_trust = float("nan")
        skip = 1  # their loop never reads row 0
        for run in runs.itertuples(index=False):
            before, previous_trust = previous_trust, float(run.trust)
            n = int(run.rows) - skip
            skip = max(0, skip - int(run.rows))
            if n <= 0:
                continue
            if current is None:  # row 1 opens segment 0 unconditionally
                current = int(run.carla_road)
                sums.append(float(run.trust))
                counts.append(1)
                entry.append(float(run.trust))
                n -= 1
                if n <= 0:
                    continue
            if not run.autopilot:
                continue
            if int(run.carla_road) != current:
                current = int(run.carla_road)
                sums.append(0.0)
                counts.append(0)
                entry.append(before)
            sums[-1] += float(run.trust) * n
            counts[-1] += n
        closed = [s / c for s, c in zip(sums[:-1], counts[:-1], strict=True) if c > 0]
        entries = entry[:-1]
        rows.append(
            {
                "episode_id": episode_id,
                "authors_segment_trust": float(np.mean(closed)) if closed else np.nan,
                "authors_intersection_trust": float(np.mean(entries)) if entries else np.nan,
                "authors_segments": len(sums) - 1,
            }
        )
    return pd.DataFrame(rows)


def authors_belief_replay(roads: pd.DataFrame, trial: int, tables, driver) -> np.ndarray:
    """The belief their policy script logged, replayed over one episode's imported roads.

    policy/policy_retrieve_trial*.py, at the arrival on road i-1 choosing road i: predict with the
    trust transition of road i's incident under the takeover seen on road i-1 (b' = T^T b, no
    likelihood weighting; the empty road keeps b), then snap b' to the nearest point (Euclidean)
    of the policy's belief grid (robot_nodes.pkl). Road 0 holds the uniform initial belief.
    Returns [n_roads, 7]."""
    grid = tables.belief_points[trial]
    roads = roads.sort_values("index")
    belief = np.full(driver.n_trust, 1.0 / driver.n_trust)
    out = [belief]
    takeovers = roads["takeover"].fillna(False).to_numpy(dtype=bool)  # null: the start road
    incidents = roads["incident"].to_numpy()
    for i in range(1, len(roads)):
        if incidents[i] != "none":
            matrix = driver.trust_transition[driver.incident_index(incidents[i]), int(takeovers[i - 1]), 0]
            predicted = matrix.T @ belief
            belief = grid[int(np.argmin(((grid - predicted) ** 2).sum(axis=1)))]
        out.append(belief)
    return np.stack(out)


def authors_paired_tests(per: pd.DataFrame) -> list[dict]:
    """The paired t-tests of statistic_test_point_based.py (scipy.stats.ttest_rel, aware vs free),
    with files paired by participant (their script pairs the i-th file of two os.listdir calls,
    which is the same pairing when both folders list the same drivers in the same order)."""
    from scipy import stats

    rows = []
    quantities = {
        "fraction of autopilot ticks with trust >= 2": "fraction_trust_at_least_2",
        "average trust (autopilot ticks)": "authors_average_trust",
        "takeover probability (free - aware)": "authors_takeover_probability",
        "LDTL satisfied (0/1)": "authors_satisfied",
    }
    subsets = {
        "authors' drivers, trial 1 (their point-based script's folders)": per[per["in_authors_subset"]]
    }
    subsets["all participants, trial 1"] = per
    for name, frame in subsets.items():
        frame = frame[frame["trial"] == 1]
        wide = frame.pivot_table(
            index="participant", columns="condition", values=list(quantities.values()), aggfunc="first"
        )
        for label, column in quantities.items():
            if (column, "aware") not in wide or (column, "free") not in wide:
                continue
            both = wide[[(column, "aware"), (column, "free")]].dropna().astype(float)
            a, b = both[(column, "aware")].to_numpy(), both[(column, "free")].to_numpy()
            if column == "authors_takeover_probability":
                a, b = b, a  # their script tests free against aware here
            note = ("fewer than 2 pairs" if len(a) < 2
                    else "every difference is 0" if np.allclose(a - b, 0) else "")
            if note:
                t, p_value = float("nan"), float("nan")
            else:
                result = stats.ttest_rel(a, b)
                t, p_value = float(result.statistic), float(result.pvalue)
            rows.append(
                {
                    "subset": name,
                    "quantity": label,
                    "pairs": int(len(a)),
                    "t_statistic": finite_or_none(t),
                    "p_value": finite_or_none(p_value),
                    "note": note,   # why no t-test was computed
                }
            )
    return rows


@dataclass
class RealStudyAnalysis:
    per_episode: pd.DataFrame
    figures: list[dict]
    matches: list[dict]
    manifest: dict
    paired_tests: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        info = self.manifest.get("real_study", {})
        columns = [
            "episode_id",
            "participant",
            "trial",
            "spec",
            "condition",
            "satisfied_logged",
            "satisfied_reported",
            "satisfied_bayes",
            "authors_satisfied",
            "authors_average_trust",
            "fraction_trust_at_least_2",
            "authors_takeover_probability",
            "mean_reported_trust",
            "in_authors_subset",
        ]
        per = self.per_episode[columns].astype(object).where(self.per_episode[columns].notna(), None)
        return {
            "participants": info.get("participants"),
            "per_episode": per.to_dict(orient="records"),
            "figures": self.figures,
            "paper_matches": self.matches,
            "authors_paired_tests": self.paired_tests,
            "missing_sessions": info.get("missing_sessions", []),
            "excluded_files": [e for e in info.get("inventory", []) if e.get("status") != "imported"],
            "authors_subsets": {k: len(v) for k, v in info.get("authors_subsets", {}).items()},
        }


def _subset_drivers(manifest: dict) -> set[int] | None:
    """Drivers in the authors' statistic_test/ folders (None when the import saw no such folder)."""
    subsets = manifest.get("real_study", {}).get("authors_subsets", {})
    names = [n for files in subsets.values() for n in files]
    if not names:
        return None

    return {int(m.group(1)) for n in names if (m := re.search(r"driver_(\d+)_", n))}


def with_real_columns(
    study_dir: Path, episodes: pd.DataFrame, roads: pd.DataFrame
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The dataset's episodes and roads joined with the imported study's real-study columns."""
    real_episodes = read_real_table(study_dir, "real_episodes")
    real_roads = read_real_table(study_dir, "real_roads")
    roads = roads.merge(real_roads, on=["episode_id", "index"], how="left", suffixes=("", "_real"))
    return episodes.merge(real_episodes, on="episode_id", how="left"), roads


def real_study_analysis(study_dir: Path, loaded: LoadedStudy | None = None) -> RealStudyAnalysis:
    """The real-study analysis of an imported study; `loaded`: the study as `load_study` read it
    (read here when not given)."""
    study_dir = Path(study_dir)
    manifest, episodes, roads = load_study(study_dir) if loaded is None else loaded
    episodes, roads = with_real_columns(study_dir, episodes, roads)
    town, driver, specs = study_inputs(manifest, study_dir)
    ticks = read_real_table(study_dir, "ticks")
    sat = satisfaction_by_source(episodes, roads, specs, town, driver.trust_levels)
    per = (
        episodes.merge(sat, on="episode_id")
        .merge(authors_point_rule(ticks), on="episode_id", how="left")
        .merge(authors_segment_rule(ticks), on="episode_id", how="left")
    )
    subset = _subset_drivers(manifest)
    per["in_authors_subset"] = per["participant"].isin(subset) if subset is not None else False
    trust_label = (f" (trust-state atoms: {REPORTED_TRUST_LABEL})"
                   if any(reads_hidden_trust(spec) for spec in specs.values()) else "")
    figures = figure_table(per, roads, ticks, subset, trust_label)
    return RealStudyAnalysis(per, figures, paper_matches(figures), manifest, authors_paired_tests(per))


def figure_table(
    per: pd.DataFrame, roads: pd.DataFrame, ticks: pd.DataFrame, subset: set[int] | None,
    trust_label: str = "",
) -> list[dict]:
    """Every reading of every figure: (figure, reading, subset, aware value, free value, n);
    trust_label is appended to the spec readings (the reported trust standing in for θ)."""
    subsets = {"all participants": per}
    if subset is not None:
        subsets["authors' statistic_test drivers"] = per[per["in_authors_subset"]]
        # the authors' scripts pair aware[i] with free[i]; a driver enters a paired analysis only
        # with both files present
    for name, frame in list(subsets.items()):
        for trial in (1, 2):
            subsets[f"{name}, trial {trial}"] = frame[frame["trial"] == trial]
    paired_drivers = {
        t: set(per[(per.trial == t) & (per.condition == "aware")]["participant"])
        & set(per[(per.trial == t) & (per.condition == "free")]["participant"])
        for t in (1, 2)
    }
    paired = per[per.apply(lambda r: r["participant"] in paired_drivers[r["trial"]], axis=1)]
    subsets["paired files only (both conditions present)"] = paired
    if subset is not None:
        subsets["authors' drivers, paired files only"] = paired[paired["in_authors_subset"]]
    pooled = _pooled_tick_trust(ticks)
    driven = roads[roads["index"] > 0]
    rows = []
    for name, frame in subsets.items():
        by = {c: frame[frame["condition"] == c] for c in ("aware", "free")}

        def add(
            figure: str, reading: str, values: dict, n: dict, kind: str = "rate", subset: str = name
        ) -> None:
            rows.append(
                {
                    "figure": figure,
                    "reading": reading,
                    "subset": subset,
                    "kind": kind,
                    "aware": values["aware"],
                    "free": values["free"],
                    "n_aware": n["aware"],
                    "n_free": n["free"],
                }
            )

        n = {c: int(len(by[c])) for c in by}
        for source in ("authors", *LOGGED_BELIEF_SOURCES):
            column = "authors_satisfied" if source == "authors" else f"satisfied_{source}"
            reading = (
                "authors' point rule (>=99% of autopilot ticks with trust >= 2)"
                if source == "authors"
                else f"phi1/phi2 on {source} beliefs{trust_label}"
            )
            add("satisfaction rate", reading, {c: _mean(by[c][column]) for c in by}, n)
            for spec in ("phi1", "phi2"):
                part = {c: by[c][by[c]["spec"] == spec] for c in by}
                add(
                    f"{spec} satisfied (count)",
                    reading,
                    {
                        c: f"{int(part[c][column].fillna(False).astype(bool).sum())}/{len(part[c])}"
                        for c in part
                    },
                    {c: int(len(part[c])) for c in part},
                    kind="count",
                )
        per_episode_trust = (
            ("authors' average: per file over autopilot ticks, then over files",
             "authors_average_trust"),
            ("authors' segment average: per CARLA road segment, then per file, then over files",
             "authors_segment_trust"),
            ("authors' intersection average: trust entering each CARLA road segment",
             "authors_intersection_trust"),
            ("trust on arrival at each road, per episode, then over episodes", "mean_reported_trust"),
        )
        for reading, column in per_episode_trust:
            add("mean trust", reading, {c: _mean(by[c][column]) for c in by}, n, kind="trust")
        add(
            "mean trust",
            "trust on arrival, pooled over every road of the subset",
            {c: _mean(driven[driven["episode_id"].isin(by[c]["episode_id"])]["reported_trust"]) for c in by},
            n,
            kind="trust",
        )
        add(
            "mean trust",
            "pooled over every tick (autopilot or not)",
            {c: _pooled_mean(pooled, by[c]["episode_id"]) for c in by},
            n,
            kind="trust",
        )
    return rows


def _pooled_tick_trust(ticks: pd.DataFrame) -> pd.DataFrame:
    t = ticks.assign(n=ticks["rows"])
    return pd.DataFrame(
        {"n": t.groupby("episode_id")["n"].sum(), "s": (t["n"] * t["trust"]).groupby(t["episode_id"]).sum()}
    )


def _pooled_mean(pooled: pd.DataFrame, ids: pd.Series) -> float | None:
    part = pooled.reindex(ids).dropna()
    return float(part["s"].sum() / part["n"].sum()) if len(part) else None


def _mean(series: pd.Series) -> float | None:
    values = pd.to_numeric(series.astype(object).where(series.notna(), np.nan), errors="coerce")
    return float(values.mean()) if values.notna().any() else None


def paper_matches(figures: list[dict]) -> list[dict]:
    """Which computed readings equal each paper figure at the paper's printed precision. The paper's
    counts are of the aware condition; they are sought among the free readings too, and such a row
    is named for the aware figure it is, sought in the free condition."""
    out = []
    # (figure, the paper's condition, the condition searched, the paper's value, its digits)
    targets: list[tuple[str, str, str, str | float, int | None]] = [
        ("phi1 satisfied (count)", "aware", "aware", paper_figures.count_text("phi1"), None),
        ("phi2 satisfied (count)", "aware", "aware", paper_figures.count_text("phi2"), None),
        ("satisfaction rate", "aware", "aware", paper_figures.SATISFACTION_RATE["aware"], 3),
        ("satisfaction rate", "free", "free", paper_figures.SATISFACTION_RATE["free"], 3),
        ("mean trust", "aware", "aware", paper_figures.MEAN_TRUST["aware"], 4),
        ("mean trust", "free", "free", paper_figures.MEAN_TRUST["free"], 4),
        ("phi1 satisfied (count)", "aware", "free", paper_figures.count_text("phi1"), None),
        ("phi2 satisfied (count)", "aware", "free", paper_figures.count_text("phi2"), None),
    ]
    for figure, paper_condition, condition, paper, digits in targets:
        hits = []
        for row in figures:
            if row["figure"] != figure or row[condition] is None:
                continue
            value = row[condition]
            if digits is None:
                # a count matches when k/n is the same
                same = value == paper
            else:
                same = round(float(value), digits) == round(float(paper), digits)
            if same:
                hits.append({"reading": row["reading"], "subset": row["subset"], "value": value})
        sought = "" if condition == paper_condition else f", sought in the {condition} condition"
        out.append({"figure": f"{figure} ({paper_condition}){sought}", "paper": paper, "reproduced_by": hits})
    return out


def format_real_study(analysis: RealStudyAnalysis, width: int | None = TERMINAL_WIDTH) -> str:
    """The real study's figures for the terminal, fitted to `width` columns (None: as wide as they are)."""
    lines = ["Real CARLA study (paper's figures are the paper's, quoted for comparison)", ""]
    # one table per subset: a row is then named by its figure and reading, which stay beside its
    # values when the table is fitted to the terminal's width
    header = ["figure", "reading", "aware", "free", "n (aware/free)"]
    subsets: dict[str, list[list[str]]] = {}
    for r in analysis.figures:
        subsets.setdefault(r["subset"], []).append(
            [
                r["figure"],
                r["reading"],
                number_text(r["aware"], 4),
                number_text(r["free"], 4),
                f"{r['n_aware']}/{r['n_free']}",
            ]
        )
    for subset, rows in subsets.items():
        lines += [f"subset: {subset}", *terminal_table(header, rows, width, keys=2), ""]
    for m in analysis.matches:
        found = (
            "; ".join(f"{h['reading']} / {h['subset']} = {number_text(h['value'], 4)}"
                      for h in m["reproduced_by"])
            or "no reading reproduces it"
        )
        lines.append(f"paper {m['figure']} = {m['paper']}: {found}")
    lines.append("")
    for test in analysis.paired_tests:
        t = number_text(test["t_statistic"], 4)
        p = MISSING if test["p_value"] is None else f"{test['p_value']:.4g}"
        why = f"{test['note']}; " if test.get("note") else ""
        lines.append(
            f"authors' paired t-test, {test['subset']}: {test['quantity']}: t = {t}, p = {p} "
            f"({why}{counted(test['pairs'], 'pair')})"
        )
    info = analysis.manifest.get("real_study", {})
    lines.append("")
    lines.append(f"missing sessions: {', '.join(info.get('missing_sessions', [])) or 'none'}")
    excluded = [e for e in info.get("inventory", []) if e.get("status") != "imported"]
    by_status: dict[str, int] = {}
    for e in excluded:
        by_status[e["status"]] = by_status.get(e["status"], 0) + 1
    lines.append("excluded files: " + ("; ".join(f"{v} {k}" for k, v in by_status.items()) or "none"))
    return "\n".join(part for line in lines for part in wrapped_text(line, width, indent="    "))


def write_real_study_report(analysis: RealStudyAnalysis, study_dir: Path) -> Path:
    path = Path(study_dir) / "real_study.json"
    path.write_text(json.dumps(analysis.to_dict(), indent=1, default=str))
    text = format_real_study(analysis, width=None)
    (Path(study_dir) / "real_study.txt").write_text(text + "\n")
    _append_to_report(Path(study_dir), text)
    return path


def _append_to_report(study_dir: Path, text: str) -> None:
    """The real-study section at the end of report.md and report.html (written just before)."""
    heading = "Real CARLA study: the paper's figures recomputed from the released logs"
    markdown = Path(study_dir) / REPORT_MARKDOWN_FILE
    if markdown.exists():
        markdown.write_text(markdown.read_text() + f"\n## {heading}\n\n```\n{text}\n```\n")
    page = Path(study_dir) / REPORT_HTML_FILE
    if page.exists():
        block = f"<h2>{html.escape(heading)}</h2><pre>{html.escape(text)}</pre>"
        content = page.read_text()
        page.write_text(
            content.replace("</body>", block + "</body>") if "</body>" in content else content + block
        )
