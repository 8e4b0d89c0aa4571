"""The consolidated dataset of a study and its manifest.

From the per-episode parts, in plan order (participant, position), whatever order they finished
(file names, schemas and manifest keys: trustroute.core.dataset, docs/dataset.md):
    episodes.parquet    one row per finished episode: the plan (participant, position, spec,
                        condition, seed) and the episode summary, plus reported-trust statistics
    roads.parquet       every episode's roads table, concatenated
    kinematics.parquet  SUMO only
    manifest.json       config and its hash, package versions, git revision, per-episode seeds,
                        counts, failures, the exact values of the policies (policies.evaluation.plain),
                        and the study's own copies of its input files (harness/study/inputs.py:
                        inputs/, by content hash; the config names them by relative paths)
Only `wall_seconds` differs between two runs of the same config; everything else is a function of
the config (tests/harness/test_study_runner.py checks this across kills, resumes and backends).

Consolidation verifies every part again (harness/study/parts.py: checksum, tables, episode ids)
and refuses damaged ones (`DamagedParts`: they are moved aside; the runner re-runs them). It is
atomic: the old manifest is removed first, each table is replaced atomically, and the manifest,
written last, marks a consistent dataset; a consolidation cut short leaves no manifest, and the
next run consolidates again.
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from trustroute.app.engines import ENGINES
from trustroute.core.dataset import (
    EPISODES_FILE,
    EPISODES_SCHEMA,
    INCIDENTS_FILE,
    KINEMATICS_FILE,
    KINEMATICS_SCHEMA,
    MANIFEST_FILE,
    MANIFEST_KEYS,
    ROADS_FILE,
    ROADS_SCHEMA,
    table_from_columns,
    write_table,
)
from trustroute.core.output_files import atomic_write_text
from trustroute.core.progress import bar_disable
from trustroute.harness.simulation.manual_measures import episode_measures
from trustroute.harness.study.context import StudyContext
from trustroute.harness.study.inputs import store_inputs
from trustroute.harness.study.parts import read_failures
from trustroute.harness.study.plan import EpisodeTask, participant_types
from trustroute.harness.study.resume import read_parts

PACKAGES: tuple[str, ...] = (
    "trustroute",
    "numpy",
    "scipy",
    "pandas",
    "pyarrow",
    "eclipse-sumo",
    "libsumo",
    "sumolib",
    "dask",
    "distributed",
    "matplotlib",
    "rerun-sdk",
    "pomdp-py",
)
REPO_ROOT = Path(__file__).resolve().parents[2]


def package_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def git_revision() -> str:
    """The repository's HEAD commit (with "+dirty" when the tree has changes), or "unknown"."""
    try:
        head = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def _reported(reports: pa.ChunkedArray) -> tuple[float | None, int]:
    """(mean of the reports given, how many); None when there was none (a null in the table)."""
    count = len(reports) - reports.null_count
    return (pc.mean(reports).as_py() if count else None), count


def episode_row(task: EpisodeTask, summary: dict, tables: dict[str, pa.Table],
                types: list[str] | None) -> dict:
    """The episodes-table row of the episode `task` from its summary and its roads and incidents
    tables; `types` are the participants' driver types (`participant_types`), None without them."""
    mean_reported, reports = _reported(tables["roads"].column("reported_trust"))
    return {
        "episode_id": task.episode_id,
        "participant": task.participant,
        "position": task.position,
        "spec": task.spec,
        "condition": task.condition,
        "seed": task.seed,
        **{k: v for k, v in summary.items() if k != "episode_id"},
        "mean_reported_trust": mean_reported,
        "reports": reports,
        "driver_type": None if types is None else types[task.participant],
        **episode_measures(tables["incidents"].to_pylist()),
    }


def consolidate(
    study_dir: Path,
    context: StudyContext,
    tasks: list[EpisodeTask],
    config_hash: str,
    expected: dict | None = None,
    run_info: dict | None = None,
    progress: bool = False,
) -> dict:
    """Write episodes/roads/kinematics Parquet files and manifest.json of the study whose context is
    `context` (its config; the inputs stored with it); return the manifest. Raises DamagedParts
    (after moving them aside) when a part fails verification."""
    from tqdm import tqdm

    study_dir = Path(study_dir)
    config = context.config
    types = participant_types(config)
    episode_rows, roads_tables, kinematics_tables, incident_tables = [], [], [], []
    parts, damaged = read_parts(study_dir, tasks)
    for task in tqdm(tasks, desc="consolidating", unit="episode", disable=bar_disable(progress),
                     leave=False, dynamic_ncols=True):
        part = parts.get(task.episode_id)
        if part is None:
            continue
        episode_rows.append(episode_row(task, part.summary, part.tables, types))
        roads_tables.append(part.tables["roads"])
        if part.tables["kinematics"].num_rows:
            kinematics_tables.append(part.tables["kinematics"])
        if part.tables["incidents"].num_rows:
            incident_tables.append(part.tables["incidents"])
    if damaged:
        raise DamagedParts(damaged)
    (study_dir / MANIFEST_FILE).unlink(missing_ok=True)  # no manifest until the tables are consistent
    episodes = table_from_columns(
        {name: [row[name] for row in episode_rows] for name in EPISODES_SCHEMA.names}, EPISODES_SCHEMA
    )
    write_table(episodes, study_dir / EPISODES_FILE)
    roads = pa.concat_tables(roads_tables) if roads_tables else ROADS_SCHEMA.empty_table()
    write_table(roads, study_dir / ROADS_FILE)
    if kinematics_tables:
        write_table(pa.concat_tables(kinematics_tables), study_dir / KINEMATICS_FILE)
    elif ENGINES[config.engine].drives_sumo:   # SUMO logs kinematics: the table exists, if empty
        write_table(KINEMATICS_SCHEMA.empty_table(), study_dir / KINEMATICS_FILE)
    if incident_tables:
        write_table(pa.concat_tables(incident_tables), study_dir / INCIDENTS_FILE)
    failures = read_failures(study_dir)

    recorded_config, inputs = store_inputs(study_dir, context)
    manifest = {
        "study": config.name,
        "config_path": recorded_config["source_path"],
        "config": recorded_config,
        "config_hash": config_hash,
        "engine": config.engine,
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "git_revision": git_revision(),
        "packages": package_versions(),
        "command": sys.argv,
        "planned_episodes": len(tasks),
        "finished_episodes": len(episode_rows),
        "failed_episodes": [
            {"episode_id": f.get("episode_id"), "error": f.get("error"), "attempts": f.get("attempts")}
            for f in failures
        ],
        "seeds": {
            "study": config.seed,
            "episodes": {t.episode_id: t.seed for t in tasks},
            "derivation": "numpy SeedSequence(study seed, spawn_key=(1, participant, spec index, "
            "condition index)); drivers of a [population]: spawn_key=(2,); true types of a [drivers] "
            "population: spawn_key=(3, participant)",
        },
        "files": {
            "episodes": EPISODES_FILE,
            "roads": ROADS_FILE,
            **({"kinematics": KINEMATICS_FILE} if ENGINES[config.engine].drives_sumo else {}),
            **({"incidents": INCIDENTS_FILE} if incident_tables else {}),
        },
        "expected": expected or {},
        "run": run_info or {},
        "inputs": inputs,
    }
    if tuple(manifest) != MANIFEST_KEYS:  # the dataset's definition and this writer must agree
        raise RuntimeError(f"manifest keys {tuple(manifest)} differ from the dataset's {MANIFEST_KEYS}")

    atomic_write_text(study_dir / MANIFEST_FILE, json.dumps(manifest, indent=1, default=_jsonable),
                      "study manifest", "free disk space or pass a writable --out, then rerun")
    return manifest


class DamagedParts(Exception):
    """Parts that failed verification at consolidation (moved aside; their episodes must re-run)."""

    def __init__(self, episode_ids: list[str]) -> None:
        self.episode_ids = list(episode_ids)
        super().__init__(f"{len(episode_ids)} damaged parts: {', '.join(episode_ids[:5])}")


def _jsonable(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)
