"""Spec satisfaction of logged episodes, re-evaluated from the logs with a chosen belief source.

The trace of an episode is its logged roads (row 0 = the start road, position 0) labelled by a
belief per position. Two ways of labelling (the study's "reference" and "true" sources are roads
whose belief_after analysis/belief_sources.py replaced, evaluated as "filter"; docs/study.md):

- "filter": the AV's online Bayes filter, the `belief_after` column (what the vehicle believed;
  the episode itself ended on this source, so it reproduces the logged `satisfied`);
- "reported": beliefs induced from the driver's reported trust, as the paper evaluated its
  participants: a point mass on the last reported level, carried forward between reports;
  positions before the first report keep the AV's initial belief (row 0's `belief_after`).
  With the paper's hightrust atom P(θ ≥ 6) > 0.5 this means "the last report was 6 or 7".

Evaluation goes through policies.trace.evaluate_traces (one vectorised DFA run for all episodes).

Specs with trust-state atoms also read the trust at each position (docs/trust_states.md, "Logged
traces"): in simulated studies the true trust, logged as `trust_after` (TRUST_SOURCES "true"); on
real logs, where the true trust is never known, the reported trust stands in for θ ("reported":
the last report at or before the position, the first report before it), and results say so
(REPORTED_TRUST_LABEL).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from trustroute.networks.town import Town
from trustroute.policies.belief.observed import reported_beliefs as reported_beliefs
from trustroute.policies.belief.problem import reads_hidden_trust
from trustroute.policies.logic.spec import Spec
from trustroute.policies.logic.trace import evaluate_traces

# Belief sources of one evaluation: the roads' `belief_after` as given ("filter"; the other
# filters of analysis/belief_sources.py arrive here as roads whose belief_after they replaced) or
# induced from reported trust.
EVALUATED_SOURCES: tuple[str, ...] = ("filter", "reported")
# Real study logs (analysis/carla_study/analysis.py): the belief the AV logged, induced from reports,
# or Bayes.
LOGGED_BELIEF_SOURCES: tuple[str, ...] = ("logged", "reported", "bayes")
# What trust-state atoms read: the true trust (simulation) or the reported trust as θ (real logs).
TRUST_SOURCES: tuple[str, ...] = ("true", "reported")
REPORTED_TRUST_LABEL = "reported trust as θ"


def trust_indices(roads: pd.DataFrame, lengths: np.ndarray, reports: np.ndarray, levels: tuple[int, ...],
                  source: str) -> np.ndarray:
    """int [n, T]: the trust level index each position's trust-state atoms read (roads sorted and
    padded as by _padded)."""
    n, horizon = reports.shape
    lookup = {level: i for i, level in enumerate(levels)}
    if source == "true":
        roads = roads.sort_values(["episode_id", "index"], kind="stable")
        flat = roads["trust_after"].to_numpy(dtype=np.int64, na_value=-1)
        unknown = sorted({int(v) for v in flat} - set(lookup))
        if unknown:
            raise ValueError(f"trust_after {unknown[0]} is not a trust level of the model {levels} "
                             "(trust-state atoms need the true trust of a simulated study)")
        row = np.repeat(np.arange(n), lengths)
        col = np.concatenate([np.arange(k) for k in lengths]) if n else np.zeros(0, dtype=np.int64)
        out = np.zeros((n, horizon), dtype=np.int64)
        out[row, col] = [lookup[int(v)] for v in flat]
        return out
    if source != "reported":
        raise ValueError(f"unknown trust source {source!r}; use one of {TRUST_SOURCES}")
    out = np.full((n, horizon), -1, dtype=np.int64)
    last = np.full(n, -1, dtype=np.int64)
    for t in range(horizon):
        reported = reports[:, t] >= 0
        if reported.any():
            values = reports[reported, t]
            bad = sorted({int(v) for v in values} - set(lookup))
            if bad:
                raise ValueError(f"reported trust {bad[0]} is not a trust level of the model {levels}")
            last[reported] = [lookup[int(v)] for v in values]
        out[:, t] = last
    first = np.where(out >= 0, out, np.iinfo(np.int64).max).min(axis=1)
    never = first == np.iinfo(np.int64).max
    if never.any():
        raise ValueError(f"{int(never.sum())} episodes have no trust report: the reported trust "
                         "cannot stand in for θ there")
    return np.where(out >= 0, out, first[:, None])


def _padded(
    roads: pd.DataFrame, town: Town, n_trust: int
) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(episode ids, states [n, T], filter beliefs [n, T, k], reports [n, T], lengths [n])."""
    roads = roads.sort_values(["episode_id", "index"], kind="stable")
    ids, starts, lengths = np.unique(roads["episode_id"].to_numpy(), return_index=True, return_counts=True)
    n, horizon = ids.size, int(lengths.max()) if ids.size else 0
    road_index = {road: i for i, road in enumerate(town.states)}
    x_flat = roads["directed_road"].map(road_index).to_numpy()
    if np.isnan(x_flat.astype(float)).any():
        raise ValueError("the logs name roads that are not in the town the spec is evaluated on")
    belief_flat = np.stack(roads["belief_after"].to_numpy()) if len(roads) else np.zeros((0, n_trust))
    report_flat = roads["reported_trust"].to_numpy(dtype=np.int64, na_value=-1)  # -1 here: no report
    row = np.repeat(np.arange(n), lengths)
    col = np.arange(len(roads)) - np.repeat(starts, lengths)
    states = np.zeros((n, horizon), dtype=np.int64)
    beliefs = np.zeros((n, horizon, belief_flat.shape[1]))
    reports = np.full((n, horizon), -1, dtype=np.int64)
    states[row, col] = x_flat.astype(np.int64)
    beliefs[row, col] = belief_flat
    reports[row, col] = report_flat
    return [str(i) for i in ids], states, beliefs, reports, lengths


def episode_satisfaction(
    roads: pd.DataFrame,
    episodes: pd.DataFrame,
    specs: dict[str, Spec],
    town: Town,
    trust_levels: tuple[int, ...],
    source: str = "filter",
    trust_source: str = "true",
) -> pd.DataFrame:
    """Per episode: `episode_id`, `satisfied` and `first_accepting` (position, -1 if never) of the
    spec the episode was driven for (episodes["spec"]), on beliefs from `source`; trust-state atoms
    read the trust from `trust_source` (TRUST_SOURCES)."""
    if source not in EVALUATED_SOURCES:
        raise ValueError(f"unknown belief source {source!r}; use one of {EVALUATED_SOURCES}")
    frames = []
    for spec_name, group in episodes.groupby("spec", sort=True):
        spec = specs[spec_name]
        spec_roads = roads[roads["episode_id"].isin(set(group["episode_id"]))]
        ids, states, beliefs, reports, lengths = _padded(spec_roads, town, len(trust_levels))
        if not ids:
            continue
        if source == "reported":
            beliefs = reported_beliefs(beliefs, reports, trust_levels)
        trust = (trust_indices(spec_roads, lengths, reports, trust_levels, trust_source)
                 if reads_hidden_trust(spec) else None)
        result = evaluate_traces(spec, town, states, beliefs, lengths, trust=trust)
        frames.append(
            pd.DataFrame(
                {"episode_id": ids, "satisfied": result.satisfied, "first_accepting": result.first_accepting}
            )
        )
    if not frames:
        return pd.DataFrame(
            {
                "episode_id": pd.Series(dtype=str),
                "satisfied": pd.Series(dtype=bool),
                "first_accepting": pd.Series(dtype="int64"),
            }
        )
    out = pd.concat(frames, ignore_index=True)
    order = {eid: i for i, eid in enumerate(episodes["episode_id"])}
    return out.sort_values("episode_id", key=lambda s: s.map(order)).reset_index(drop=True)


def satisfaction_by_source(
    episodes: pd.DataFrame, roads: pd.DataFrame, specs: dict, town, trust_levels
) -> pd.DataFrame:
    """Per episode (with a spec): satisfied_logged, satisfied_reported, satisfied_bayes. Real logs:
    trust-state atoms read the reported trust as θ (REPORTED_TRUST_LABEL)."""
    out = episodes[["episode_id"]].copy()
    analysed = episodes[episodes["spec"].isin(list(specs))]
    for source in LOGGED_BELIEF_SOURCES:
        variant = roads
        if source == "logged":
            variant = roads.assign(belief_after=roads["logged_belief"])
        result = episode_satisfaction(
            variant, analysed, specs, town, trust_levels, "reported" if source == "reported" else "filter",
            trust_source="reported",
        )
        mapped = dict(zip(result["episode_id"], result["satisfied"], strict=True))
        out[f"satisfied_{source}"] = out["episode_id"].map(mapped).astype("boolean")
    return out
