"""Spec satisfaction of logged episodes, re-evaluated from the logs with a chosen belief source.

The trace of an episode is its logged roads (row 0 = the start road, position 0) labelled by a
belief per position. Two belief sources (DESIGN.md, "The study"):

- "filter": the AV's online Bayes filter, the `belief_after` column (what the vehicle believed;
  the episode itself ended on this source, so it reproduces the logged `satisfied`);
- "reported": beliefs induced from the driver's reported trust, as the paper evaluated its
  participants: a point mass on the last reported level, carried forward between reports;
  positions before the first report keep the AV's initial belief (row 0's `belief_after`).
  With the paper's hightrust atom P(θ ≥ 6) > 0.5 this means "the last report was 6 or 7".

Evaluation goes through policies.trace.evaluate_traces (one vectorised DFA run for all episodes).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from trustroute.networks.town import Town
from trustroute.policies.logic.spec import Spec
from trustroute.policies.logic.trace import evaluate_traces

BELIEF_SOURCES: tuple[str, ...] = ("filter", "reported")


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


def reported_beliefs(filter_beliefs: np.ndarray, reports: np.ndarray, levels: tuple[int, ...]) -> np.ndarray:
    """Point mass on the last reported level (carried forward); before any report, the AV's
    initial belief (position 0 of the filter)."""
    n, horizon, k = filter_beliefs.shape
    out = np.repeat(filter_beliefs[:, :1, :], horizon, axis=1)
    lookup = np.full(max(levels) + 2, -1, dtype=np.int64)
    lookup[list(levels)] = np.arange(len(levels))
    last = np.full(n, -1, dtype=np.int64)
    for t in range(horizon):
        reported = reports[:, t] >= 0
        last[reported] = lookup[np.minimum(reports[reported, t], lookup.size - 1)]
        has = np.flatnonzero(last >= 0)
        out[has, t, :] = 0.0
        out[has, t, last[has]] = 1.0
    return out


def episode_satisfaction(
    roads: pd.DataFrame,
    episodes: pd.DataFrame,
    specs: dict[str, Spec],
    town: Town,
    trust_levels: tuple[int, ...],
    source: str = "filter",
) -> pd.DataFrame:
    """Per episode: `episode_id`, `satisfied` and `first_accepting` (position, -1 if never) of the
    spec the episode was driven for (episodes["spec"]), on beliefs from `source`."""
    if source not in BELIEF_SOURCES:
        raise ValueError(f"unknown belief source {source!r}; use one of {BELIEF_SOURCES}")
    frames = []
    for spec_name, group in episodes.groupby("spec", sort=True):
        spec = specs[spec_name]
        spec_roads = roads[roads["episode_id"].isin(set(group["episode_id"]))]
        ids, states, beliefs, reports, lengths = _padded(spec_roads, town, len(trust_levels))
        if not ids:
            continue
        if source == "reported":
            beliefs = reported_beliefs(beliefs, reports, trust_levels)
        result = evaluate_traces(spec, town, states, beliefs, lengths)
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
