"""Writing and verifying episode parts: one checksummed part per episode vs one Parquet file per table.

Baseline (what studies wrote before): per episode three Parquet files (roads, kinematics,
incidents), each written to a temporary file, fsynced and renamed. Now: one part per episode
holding all three tables (harness/study/parts.py), renamed into place without an fsync, and one
file-system sync per 64 parts. Also the part with an fsync of its own (`sync=True`), and the time
to read and fully verify a part (checksum, every table's schema and ids). Tables have the sizes
of a SUMO episode (11 roads, 400 kinematics rows, 4 incidents), converted to Arrow beforehand
(the pandas conversion is common to both layouts). All in one run: ratios only.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from trustroute.core.dataset import INCIDENTS_SCHEMA, KINEMATICS_SCHEMA, ROADS_SCHEMA, table_from_frame
from trustroute.harness.study.parts import read_part, sync_parts, write_part_tables
from trustroute.harness.study.plan import EpisodeTask

EPISODES = 300
SYNC_EVERY = 64


def _frames(episode_id: str, rng: np.random.Generator) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    n = 11
    roads = pd.DataFrame({
        "episode_id": episode_id, "index": np.arange(n), "directed_road": ["A-B"] * n,
        "action": ["C"] * (n - 1) + [None], "incident": ["none"] * n,
        "takeover": [None] + [False] * (n - 1), "performance": [None] + ["succ"] * (n - 1),
        "trust_before": rng.integers(1, 8, n), "trust_after": rng.integers(1, 8, n),
        "reported_trust": rng.integers(1, 8, n), "belief_before": [list(rng.dirichlet(np.ones(7)))] * n,
        "belief_after": [list(rng.dirichlet(np.ones(7)))] * n, "dfa_state": np.zeros(n, dtype=np.int64),
        "fallback": [False] * n, "sim_time_in": rng.random(n), "sim_time_out": rng.random(n),
    })
    k = 400
    kinematics = pd.DataFrame({
        "episode_id": episode_id, "time": np.arange(k) * 0.5, "x": rng.random(k), "y": rng.random(k),
        "speed": rng.random(k), "lane": ["A-B_1"] * k, "mode": ["auto"] * k,
    })
    m = 4
    incidents = pd.DataFrame({name: [None] * m for name in INCIDENTS_SCHEMA.names})
    incidents = incidents.assign(
        episode_id=episode_id, index=np.arange(m), directed_road="A-B", incident="truck", takeover=False,
        performance="succ", min_ttc=np.inf, max_deceleration=1.0, collided=False, min_head_on_ttc=np.inf,
        min_pedestrian_distance=np.inf, time_lost=0.0)
    return roads, kinematics, incidents


def _task(i: int) -> EpisodeTask:
    return EpisodeTask(episode_id=f"p{i:05d}-phi1-free", participant=i, position=0, spec="phi1", spec_index=0,
                       condition="free", condition_index=0, seed=i, driver_entropy=(1, 1, i, 0, 0))


def _per_table_parquet(folder: Path, episode_id: str, tables: dict[str, pa.Table]) -> None:
    for name, table in tables.items():
        path = folder / name / f"{episode_id}.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        temp = path.with_name(".tmp-" + path.name)
        pq.write_table(table, temp, write_page_checksum=True)
        with open(temp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(temp, path)


def _tables(episode_id: str, rng: np.random.Generator) -> dict[str, pa.Table]:
    roads, kinematics, incidents = _frames(episode_id, rng)
    return {"roads": table_from_frame(roads, ROADS_SCHEMA),
            "kinematics": table_from_frame(kinematics, KINEMATICS_SCHEMA),
            "incidents": table_from_frame(incidents, INCIDENTS_SCHEMA)}


def run() -> list[dict]:
    rng = np.random.default_rng(1)
    # Converted to Arrow up front: the pandas conversion is the same for both layouts and is not
    # what is measured here.
    episodes = [(_task(i), _tables(_task(i).episode_id, rng)) for i in range(EPISODES)]
    summary = {"episode_id": "", "junctions": 10}
    with tempfile.TemporaryDirectory(prefix="trustroute-bench-parts-", dir=Path.cwd()) as folder:
        root = Path(folder)
        started = time.perf_counter()
        for task, tables in episodes:
            _per_table_parquet(root / "baseline", task.episode_id, tables)
        baseline = time.perf_counter() - started

        started = time.perf_counter()
        for i, (task, tables) in enumerate(episodes):
            write_part_tables(root / "batched", task, {**summary, "episode_id": task.episode_id}, tables)
            if (i + 1) % SYNC_EVERY == 0:
                sync_parts(root / "batched")
        sync_parts(root / "batched")
        batched = time.perf_counter() - started

        started = time.perf_counter()
        for task, tables in episodes:
            write_part_tables(root / "synced", task, {**summary, "episode_id": task.episode_id}, tables,
                              sync=True)
        synced = time.perf_counter() - started

        parts = sorted((root / "batched" / "parts").glob("*.zip"))
        started = time.perf_counter()
        for path in parts:
            read_part(path)
        verify = time.perf_counter() - started
    common = {"episodes": EPISODES, "baseline_what": "3 Parquet files per episode, each fsynced"}
    return [
        {"name": "parts.write.batched_sync.seconds_per_episode", "value": batched / EPISODES, "unit": "s",
         "baseline": baseline / EPISODES, "ratio": batched / baseline, **common},
        {"name": "parts.write.fsync_each.seconds_per_episode", "value": synced / EPISODES, "unit": "s",
         "baseline": baseline / EPISODES, "ratio": synced / baseline, **common},
        {"name": "parts.read_and_verify.seconds_per_episode", "value": verify / EPISODES, "unit": "s",
         "episodes": EPISODES},
    ]
