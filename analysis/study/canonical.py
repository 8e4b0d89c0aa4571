"""The analysis' order of a study's participants: one given by their data, not by their numbers.

The bootstrap intervals resample participants (and episodes) by their place in the tables, the
tables sort by participant, and a floating-point sum depends on the order of its terms. A package
of `trustroute export` renames every participant to a random code and sorts its rows by code
(docs/live_studies.md, "Export"), so an analysis in the tables' order would give a reviewer other
intervals, and other last digits, than the study's own report. The analysis therefore renumbers the
participants 0, 1, ... in the order of a digest of what each one's episodes and roads hold, leaving
out what an export changes or drops (the ids, the seeds) and the wall-clock time (the one column
that differs between two runs of a study, docs/dataset.md), and puts every table's rows in that
order: the same data under any names, in any row order, is the same analysis, bit for bit.
Participants of equal digests hold the same episodes and roads, so their order changes nothing the
analysis computes from those; they keep the order of their rows.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pandas as pd

# episodes' columns an export renames or drops, or that differ between runs of one config
UNSTABLE_EPISODE_COLUMNS = ("episode_id", "participant", "seed", "wall_seconds")


def _is_list_column(values: pd.Series) -> bool:
    first = values.dropna().head(1)
    return values.dtype == object and len(first) > 0 and isinstance(first.iloc[0], list | np.ndarray)


def _row_hashes(frame: pd.DataFrame) -> np.ndarray:
    """One 64-bit hash per row of `frame`'s values; a list column (a belief, one length per table,
    docs/dataset.md) as its entries, one column each."""
    listed = [c for c in frame.columns if _is_list_column(frame[c])]
    spread = [pd.DataFrame(np.vstack(frame[c].to_numpy()), index=frame.index).add_prefix(f"{c}.")
              for c in listed]
    flat = pd.concat([frame.drop(columns=listed), *spread], axis=1)
    return pd.util.hash_pandas_object(flat, index=False).to_numpy()


def participant_ranks(episodes: pd.DataFrame, roads: pd.DataFrame) -> dict[int, int]:
    """participant -> 0-based rank in the order of the digests of their episodes (by position) and
    their episodes' roads (module docstring); equal digests keep the order of first appearance."""
    if not len(episodes):
        return {}
    stable = episodes.drop(columns=[c for c in UNSTABLE_EPISODE_COLUMNS if c in episodes])
    owner = dict(zip(episodes["episode_id"], episodes["participant"], strict=True))
    position = dict(zip(episodes["episode_id"], episodes["position"], strict=True))
    parts: dict[int, list[tuple]] = {}
    for episode, participant, row_hash in zip(episodes["episode_id"], episodes["participant"],
                                              _row_hashes(stable), strict=True):
        parts.setdefault(int(participant), []).append((int(position[episode]), -1, int(row_hash)))
    road_hashes = _row_hashes(roads.drop(columns=["episode_id"])) if len(roads) else np.empty(0, np.uint64)
    for episode, index, row_hash in zip(roads["episode_id"], roads["index"], road_hashes, strict=True):
        if episode in owner:
            parts[int(owner[episode])].append((int(position[episode]), int(index), int(row_hash)))
    digests = {p: hashlib.sha256(repr(sorted(rows)).encode()).hexdigest() for p, rows in parts.items()}
    appearance = list(dict.fromkeys(int(p) for p in episodes["participant"]))
    ordered = sorted(appearance, key=lambda p: digests[p])   # stable: ties keep appearance order
    return {p: rank for rank, p in enumerate(ordered)}


def in_rank_order(frame: pd.DataFrame, rank_of_episode: dict[str, int]) -> pd.DataFrame:
    """`frame`'s rows by their episode's participant rank, each participant's in their own order."""
    if not len(frame):
        return frame
    ranks = frame["episode_id"].map(rank_of_episode).to_numpy()
    return frame.iloc[np.argsort(ranks, kind="stable")].reset_index(drop=True)


def renumbered(frame: pd.DataFrame, rank_of_episode: dict[str, int]) -> pd.DataFrame:
    """`frame` (one row per episode, with its participant) in rank order, `participant` its rank."""
    ordered = in_rank_order(frame, rank_of_episode)
    return ordered.assign(participant=ordered["episode_id"].map(rank_of_episode).astype("int64"))


def canonical_tables(episodes: pd.DataFrame, roads: pd.DataFrame, *per_episode: pd.DataFrame
                     ) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, int], list[pd.DataFrame]]:
    """(episodes `renumbered`, roads in rank order, episode id -> rank, each table of `per_episode`
    (one row per episode, such as the satisfaction computed before the ranks) `renumbered`): what
    the analysis computes from them is the same for any participant names and row order (module
    docstring)."""
    ranks = participant_ranks(episodes, roads)
    rank_of_episode = {e: ranks[int(p)] for e, p in zip(episodes["episode_id"], episodes["participant"],
                                                         strict=True)}
    return (renumbered(episodes, rank_of_episode), in_rank_order(roads, rank_of_episode), rank_of_episode,
            [renumbered(frame, rank_of_episode) for frame in per_episode])
