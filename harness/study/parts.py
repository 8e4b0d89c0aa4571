"""One Parquet part per episode, written atomically; what a rerun may skip; failure records.

Layout of a study directory (all written here; names and schemas: trustroute.analysis.dataset,
docs/dataset.md):
    parts/<episode_id>.parquet        the episode's roads table; its schema metadata holds the
                                      episode summary and the planned task (JSON)
    kinematics/<episode_id>.parquet   SUMO only, written before the roads part
    incidents/<episode_id>.parquet    SUMO only (incident objects, takeovers), before the roads part
    failures/<episode_id>.json        the last error of an episode that failed (cleared on success)

A part is written to a temporary file in the same folder and renamed into place (os.replace is
atomic on POSIX), so a killed run leaves either a whole part or none; the roads part is written
last and is the commit mark of an episode. Parquet page checksums are written and verified on
read, so a part whose bytes were damaged later is detected (`PartError`) and the episode re-run.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from trustroute.analysis.dataset import (
    DAMAGED_DIR,
    FAILURES_DIR,
    INCIDENTS_SCHEMA,
    KINEMATICS_SCHEMA,
    PART_FOLDERS,
    PART_SUMMARY_KEY,
    PART_TASK_KEY,
    ROADS_SCHEMA,
    SchemaError,
    check_table,
    failure_path,
    incidents_part_path,
    kinematics_part_path,
    part_path,
    table_from_frame,
)
from trustroute.harness.study.plan import EpisodeTask

TEMP_PREFIX = ".tmp-"


class PartError(Exception):
    """A part file that cannot be trusted (truncated, damaged, inconsistent)."""


def _atomic_write_table(table: pa.Table, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = path.with_name(f"{TEMP_PREFIX}{path.name}.{os.getpid()}")
    try:
        pq.write_table(table, temp, write_page_checksum=True)
        with open(temp, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(temp, path)
    finally:
        if temp.exists():
            temp.unlink()


def _atomic_write_text(text: str, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    temp = path.with_name(f"{TEMP_PREFIX}{path.name}.{os.getpid()}")
    temp.write_text(text)
    os.replace(temp, path)


def _plain(value: object) -> object:
    """numpy scalars as JSON values."""
    item = getattr(value, "item", None)
    return item() if callable(item) else value


def write_part(
    study_dir: Path,
    task: EpisodeTask,
    summary: dict,
    roads: pd.DataFrame,
    kinematics: pd.DataFrame | None = None,
    incidents: pd.DataFrame | None = None,
) -> Path:
    """Write an episode's kinematics and incidents (SUMO) and then its roads part, each atomically."""
    if incidents is not None and len(incidents):
        _atomic_write_table(table_from_frame(incidents, INCIDENTS_SCHEMA),
                            incidents_part_path(study_dir, task.episode_id))
    if kinematics is not None and len(kinematics):
        _atomic_write_table(table_from_frame(kinematics, KINEMATICS_SCHEMA),
                            kinematics_part_path(study_dir, task.episode_id))
    table = table_from_frame(roads, ROADS_SCHEMA)
    metadata = {
        PART_SUMMARY_KEY: json.dumps({k: _plain(v) for k, v in summary.items()}).encode(),
        PART_TASK_KEY: json.dumps(asdict(task)).encode(),
    }
    table = table.replace_schema_metadata(metadata)
    path = part_path(study_dir, task.episode_id)
    _atomic_write_table(table, path)
    failure = failure_path(study_dir, task.episode_id)
    if failure.exists():
        failure.unlink()
    return path


def read_part_table(path: Path) -> tuple[dict, dict, pa.Table]:
    """(summary, task, roads as an Arrow table) of a part; PartError when damaged or inconsistent."""
    try:
        table = pq.read_table(path, page_checksum_verification=True)
        metadata = table.schema.metadata or {}
        summary = json.loads(metadata[PART_SUMMARY_KEY])
        task = json.loads(metadata[PART_TASK_KEY])
    except Exception as exc:  # any failure to read is a damaged part
        raise PartError(f"{path}: {type(exc).__name__}: {exc}") from None
    try:
        table = check_table(table.replace_schema_metadata(None), ROADS_SCHEMA, str(path))
    except SchemaError as exc:
        raise PartError(str(exc)) from None
    episode = task.get("episode_id")
    if summary.get("episode_id") != episode or Path(path).stem != episode:
        raise PartError(f"{path}: belongs to episode {episode!r}")
    ids = table.column("episode_id")
    if table.num_rows != int(summary.get("junctions", -1)) + 1 or not pc.all(pc.equal(ids, episode)).as_py():
        raise PartError(f"{path}: {table.num_rows} rows for {summary.get('junctions')} junctions")
    return summary, task, table


def finished_episodes(study_dir: Path, tasks: list[EpisodeTask]) -> tuple[set[str], list[str]]:
    """(episode ids with a valid part, episode ids whose part was damaged and has been removed).

    Also removes temporary files a killed run left behind. A part whose recorded task differs
    from the plan (another config wrote it) counts as damaged.
    """
    study_dir = Path(study_dir)
    for folder in PART_FOLDERS:
        for temp in (study_dir / folder).glob(f"{TEMP_PREFIX}*"):
            temp.unlink(missing_ok=True)
    done: set[str] = set()
    damaged: list[str] = []
    for task in tasks:
        path = part_path(study_dir, task.episode_id)
        if not path.exists():
            continue
        try:
            _, recorded, _ = read_part_table(path)
            if recorded != json.loads(json.dumps(asdict(task))):
                raise PartError(f"{path}: written for a different plan")
        except PartError:
            damaged.append(task.episode_id)
            quarantine = study_dir / DAMAGED_DIR / path.name
            quarantine.parent.mkdir(parents=True, exist_ok=True)
            os.replace(path, quarantine)
            continue
        done.add(task.episode_id)
    return done, damaged


def write_failure(study_dir: Path, task: EpisodeTask, error: str, traceback_text: str, attempts: int) -> None:
    record = {
        "episode_id": task.episode_id,
        "attempts": attempts,
        "error": error,
        "traceback": traceback_text,
        "task": asdict(task),
    }
    _atomic_write_text(json.dumps(record, indent=1), failure_path(study_dir, task.episode_id))


def read_failures(study_dir: Path) -> list[dict]:
    folder = Path(study_dir) / FAILURES_DIR
    out = []
    for path in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        try:
            out.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError):
            out.append({"episode_id": path.stem, "error": "unreadable failure record"})
    return out
