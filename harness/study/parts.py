"""One part file per episode holding every table of it, with a checksum; resume checks; failures.

Layout of a study directory while it runs (names: trustroute.core.dataset, docs/dataset.md):
    parts/<episode_id>.zip      the episode's part: every table of the episode and its checksum
    parts/batch-<first episode_id>.zip   a batch part: several episodes' tables (model engine)
    failures/<episode_id>.json  every attempt's error of an episode that failed (cleared on success)
    damaged/<episode_id>.zip    parts found damaged, missing a table or foreign, moved aside

A part is a zip archive (stored, not compressed; fixed entry dates, so the same episode gives the
same bytes) of
    part.json           format, version, the dataset format (trustroute/core/dataset.py DATASET_FORMAT),
                        episode id, the planned task, the episode summary, and per table its row
                        count and SHA-256
    roads.arrows        the roads table        (Arrow IPC stream, trustroute.core.dataset schemas)
    kinematics.arrows   the kinematics table   (empty in the model engine)
    incidents.arrows    the incidents table    (empty in the model engine)
    checksum.sha256     SHA-256 over part.json and every table's bytes, in that order
`read_part` verifies all of it (zip CRCs, the checksum, each table's SHA-256 and schema, the
episode id of the file name, of part.json and of every row, the row count of the roads), so one
flipped bit in any table, a truncated or a swapped-in part is a `PartError`, on resume
(resume.py `finished_episodes`: the part is moved aside and the episode re-run) and again at consolidation.

A batch part (`write_batch_part`, `read_batch_part`) holds a run of episodes the model engine ran
in one task: the same entries, part.json listing every episode (task, summary, row count per
table) and each table the episodes' rows one after the other. It is verified as a whole (any
damage puts every episode of it back to run) and read back as the episodes' `Part`s, so resume
and consolidation treat an episode the same wherever it is stored.

A part is written to a temporary file beside it and renamed into place, so a killed run leaves a
whole part or none. The study does not fsync every part: it syncs the file system once per batch
(`sync_parts`) and at the end, before consolidation. A part that a power loss left incomplete
fails its checksum on resume and is re-run, so the resume guarantee does not depend on the sync.
"""

from __future__ import annotations

import ctypes
import hashlib
import io
import json
import os
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from trustroute.core.dataset import (
    ADDED_COLUMNS,
    DATASET_FORMAT,
    FAILURES_DIR,
    INCIDENTS_SCHEMA,
    KINEMATICS_SCHEMA,
    ROADS_SCHEMA,
    SchemaError,
    check_table,
    failure_path,
    part_path,
    table_from_frame,
    with_added_columns,
)
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_bytes, atomic_write_text
from trustroute.core.validation import read_input_bytes
from trustroute.harness.study.plan import EpisodeTask

PART_FORMAT = "trustroute-part"
PART_VERSION = 1
META_ENTRY = "part.json"
CHECKSUM_ENTRY = "checksum.sha256"
PART_TABLES: dict[str, pa.Schema] = {
    "roads": ROADS_SCHEMA,
    "kinematics": KINEMATICS_SCHEMA,
    "incidents": INCIDENTS_SCHEMA,
}
MAX_PART_BYTES = 1024**3
ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed: the bytes of a part depend on its content only


class PartError(Exception):
    """A part file that cannot be trusted (truncated, damaged, foreign, inconsistent)."""


@dataclass(frozen=True, eq=False)
class Part:
    """A verified part: the planned task, the episode summary and the episode's tables."""

    episode_id: str
    task: dict
    summary: dict
    tables: dict[str, pa.Table]


def _plain(value: object) -> object:
    """numpy scalars as JSON values."""
    return value.item() if isinstance(value, np.generic) else value


def _ipc_bytes(table: pa.Table) -> bytes:
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as writer:
        writer.write_table(table)
    return sink.getvalue().to_pybytes()


def _table(frame: pd.DataFrame | None, schema: pa.Schema) -> pa.Table:
    if frame is None or not len(frame):
        return schema.empty_table()
    return table_from_frame(frame, schema)


def encode_part(task: EpisodeTask, summary: dict, tables: dict[str, pa.Table]) -> bytes:
    """The bytes of a part file (deterministic: same content, same bytes)."""
    blobs = {name: _ipc_bytes(tables[name]) for name in PART_TABLES}
    meta = {
        "format": PART_FORMAT,
        "version": PART_VERSION,
        "dataset": DATASET_FORMAT,
        "episode_id": task.episode_id,
        "task": asdict(task),
        "summary": {k: _plain(v) for k, v in summary.items()},
        "tables": {name: {"rows": tables[name].num_rows, "sha256": hashlib.sha256(blob).hexdigest()}
                   for name, blob in blobs.items()},
    }
    return part_archive(meta, blobs)


def write_part(
    study_dir: Path,
    task: EpisodeTask,
    summary: dict,
    roads: pd.DataFrame,
    kinematics: pd.DataFrame | None = None,
    incidents: pd.DataFrame | None = None,
    sync: bool = False,
) -> Path:
    """Write an episode's part (all its tables, one file) atomically; clear its failure record."""
    tables = {"roads": table_from_frame(roads, ROADS_SCHEMA),
              "kinematics": _table(kinematics, KINEMATICS_SCHEMA),
              "incidents": _table(incidents, INCIDENTS_SCHEMA)}
    return write_part_tables(study_dir, task, summary, tables, sync)


def write_part_tables(study_dir: Path, task: EpisodeTask, summary: dict, tables: dict[str, pa.Table],
                      sync: bool = False) -> Path:
    """`write_part` for tables already in Arrow form (checked against their schemas here; a table
    that is absent is written empty)."""
    tables = {name: check_table(tables[name].replace_schema_metadata(None), schema, name)
              if tables.get(name) is not None else schema.empty_table()
              for name, schema in PART_TABLES.items()}
    path = part_path(study_dir, task.episode_id)
    atomic_write_bytes(path, encode_part(task, summary, tables), "episode part",
                       "free disk space or pass a writable --out, then rerun (the study resumes)", sync=sync)
    failure = failure_path(study_dir, task.episode_id)
    if failure.exists():
        failure.unlink()
    return path


def _part_entries(path: Path) -> dict[str, bytes]:
    """The part's zip entries, each CRC-checked, in the expected order, the checksum verified."""
    try:
        data = read_input_bytes(path, "episode part", MAX_PART_BYTES)
    except InputError as exc:
        raise PartError(f"{path}: {exc.problem}") from None
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            names = archive.namelist()
            expected = [META_ENTRY, *(f"{name}.arrows" for name in PART_TABLES), CHECKSUM_ENTRY]
            if names != expected:
                raise PartError(f"{path}: entries {names}, expected {expected}")
            entries = {name: archive.read(name) for name in names}  # checks each entry's CRC-32
    except PartError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError, EOFError, KeyError) as exc:
        raise PartError(f"{path}: not a readable part ({type(exc).__name__}: {exc})") from None
    checksum = hashlib.sha256(entries[META_ENTRY])
    for name in PART_TABLES:
        checksum.update(entries[f"{name}.arrows"])
    if entries[CHECKSUM_ENTRY] != checksum.hexdigest().encode():
        raise PartError(f"{path}: checksum mismatch (the part was damaged after it was written)")
    return entries


def _part_meta(path: Path, blob: bytes) -> dict:
    """part.json: of this format and dataset format, naming the file's episode throughout."""
    try:
        meta = json.loads(blob)
    except ValueError as exc:
        raise PartError(f"{path}: unreadable part.json ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != PART_FORMAT or meta.get("version") != PART_VERSION:
        raise PartError(f"{path}: not a part of format {PART_FORMAT} version {PART_VERSION}")
    if meta.get("dataset") != DATASET_FORMAT:
        raise PartError(f"{path}: dataset format {meta.get('dataset')!r}, this trustroute writes "
                        f"{DATASET_FORMAT!r} (the episode is re-run, so a study never mixes two formats)")
    episode = meta.get("episode_id")
    task, summary = meta.get("task"), meta.get("summary")
    if not (isinstance(task, dict) and isinstance(summary, dict)):
        raise PartError(f"{path}: part.json lacks the task or the summary")
    if path.stem != episode or task.get("episode_id") != episode or summary.get("episode_id") != episode:
        raise PartError(f"{path}: belongs to episode {episode!r} (a foreign part)")
    return meta


def _part_table(path: Path, name: str, blob: bytes, recorded: dict, episode: str) -> pa.Table:
    """One table of a part: its recorded SHA-256 and row count, its schema, the part's episode."""
    table = _checked_table(path, name, blob, recorded)
    if table.num_rows != recorded.get("rows"):
        raise PartError(f"{path}: table {name} has {table.num_rows} rows, part.json says "
                        f"{recorded.get('rows')}")
    if table.num_rows and not pc.all(pc.equal(table.column("episode_id"), episode)).as_py():
        raise PartError(f"{path}: table {name} holds rows of another episode")
    return table


def read_part(path: Path) -> Part:
    """A part, verified in full (module docstring); PartError naming what is wrong otherwise."""
    path = Path(path)
    entries = _part_entries(path)
    meta = _part_meta(path, entries[META_ENTRY])
    episode, task, summary = meta["episode_id"], meta["task"], meta["summary"]
    tables = {name: _part_table(path, name, entries[f"{name}.arrows"],
                                (meta.get("tables") or {}).get(name) or {}, episode)
              for name in PART_TABLES}
    if tables["roads"].num_rows != int(summary.get("junctions", -1)) + 1:
        raise PartError(f"{path}: {tables['roads'].num_rows} roads for {summary.get('junctions')} junctions")
    return Part(episode_id=episode, task=task, summary=summary, tables=tables)


def sync_parts(study_dir: Path) -> None:
    """Flush the study directory's file system to disk: one syncfs per batch of parts instead of
    an fsync per part (os.sync where syncfs is unavailable)."""
    try:
        descriptor = os.open(study_dir, os.O_RDONLY)
    except OSError:
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.syncfs(descriptor) != 0:
            os.sync()
    except (OSError, AttributeError):
        os.sync()
    finally:
        os.close(descriptor)


def write_failure(study_dir: Path, task: EpisodeTask, error: str, traceback_text: str, attempts: int,
                  errors: list[str] | None = None) -> None:
    """Record why an episode failed: the last error and its traceback, and every attempt's reason."""
    record = {
        "episode_id": task.episode_id,
        "attempts": attempts,
        "error": error,
        "errors": list(errors or [error]),
        "traceback": traceback_text,
        "task": asdict(task),
    }
    atomic_write_text(failure_path(study_dir, task.episode_id), json.dumps(record, indent=1),
                      "failure record", "free disk space, then rerun")


def read_failures(study_dir: Path) -> list[dict]:
    folder = Path(study_dir) / FAILURES_DIR
    out = []
    for path in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        try:
            out.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError):
            out.append({"episode_id": path.stem, "error": "unreadable failure record"})
    return out


# -- batch parts ---------------------------------------------------------------------------------

BATCH_FORMAT = "trustroute-batch-part"
BATCH_PREFIX = "batch-"


def batch_part_path(study_dir: Path, first_episode_id: str) -> Path:
    """Where the batch part starting with episode `first_episode_id` is written."""
    return part_path(study_dir, BATCH_PREFIX + first_episode_id)


def batch_part_paths(study_dir: Path) -> list[Path]:
    """The batch parts of a study directory, by name."""
    folder = part_path(study_dir, BATCH_PREFIX).parent
    return sorted(folder.glob(f"{BATCH_PREFIX}*.zip")) if folder.is_dir() else []


def encode_batch_part(tasks: list[EpisodeTask], summaries: list[dict], rows: list[dict[str, int]],
                      joined: dict[str, pa.Table]) -> bytes:
    """The bytes of a batch part of the episodes `tasks` (deterministic, as `encode_part`): `rows`
    the episodes' row counts per table, `joined` the tables with their rows one after the other."""
    blobs = {name: _ipc_bytes(joined[name]) for name in PART_TABLES}
    meta = {
        "format": BATCH_FORMAT,
        "version": PART_VERSION,
        "dataset": DATASET_FORMAT,
        "episodes": [{"episode_id": task.episode_id, "task": asdict(task),
                      "summary": {k: _plain(v) for k, v in summary.items()}, "rows": counts}
                     for task, summary, counts in zip(tasks, summaries, rows, strict=True)],
        "tables": {name: {"rows": joined[name].num_rows, "sha256": hashlib.sha256(blob).hexdigest()}
                   for name, blob in blobs.items()},
    }
    return part_archive(meta, blobs)


def write_batch_part(study_dir: Path, tasks: list[EpisodeTask], summaries: list[dict],
                     tables: list[dict[str, pa.Table]]) -> Path:
    """Write the batch part of `tasks` (their summaries and tables, in that order) atomically, named
    after the first episode; clear the episodes' failure records."""
    rows = [{name: t[name].num_rows if t.get(name) is not None else 0 for name in PART_TABLES}
            for t in tables]
    joined = {}
    for name, schema in PART_TABLES.items():
        present = [t[name].replace_schema_metadata(None) for t in tables if t.get(name) is not None]
        joined[name] = check_table(pa.concat_tables(present, promote_options="none"), schema, name) \
            if present else schema.empty_table()
    path = batch_part_path(study_dir, tasks[0].episode_id)
    atomic_write_bytes(path, encode_batch_part(tasks, summaries, rows, joined), "episode part",
                       "free disk space or pass a writable --out, then rerun (the study resumes)")
    for task in tasks:
        failure = failure_path(study_dir, task.episode_id)
        if failure.exists():
            failure.unlink()
    return path


def _batch_episodes(path: Path, meta: object) -> list[dict]:
    if (not isinstance(meta, dict) or meta.get("format") != BATCH_FORMAT
            or meta.get("version") != PART_VERSION):
        raise PartError(f"{path}: not a part of format {BATCH_FORMAT} version {PART_VERSION}")
    if meta.get("dataset") != DATASET_FORMAT:
        raise PartError(f"{path}: dataset format {meta.get('dataset')!r}, this trustroute writes "
                        f"{DATASET_FORMAT!r} (the episodes are re-run, so a study never mixes two formats)")
    episodes = meta.get("episodes")
    if not isinstance(episodes, list) or not episodes:
        raise PartError(f"{path}: part.json lists no episodes")
    for entry in episodes:
        ok = isinstance(entry, dict) and isinstance(entry.get("task"), dict) and isinstance(
            entry.get("summary"), dict) and isinstance(entry.get("rows"), dict)
        episode = entry.get("episode_id") if isinstance(entry, dict) else None
        if not ok or episode != entry["task"].get("episode_id") \
                or episode != entry["summary"].get("episode_id"):
            raise PartError(f"{path}: an episode entry of part.json is incomplete or inconsistent")
    if path.name != batch_part_path(path.parent.parent, episodes[0]["episode_id"]).name:
        raise PartError(f"{path}: begins with episode {episodes[0]['episode_id']!r} (a foreign part)")
    return episodes


def read_batch_part(path: Path) -> list[Part]:
    """The episodes of a batch part, verified in full as `read_part` verifies a part (every row
    belongs to the episode part.json places it in); PartError otherwise."""
    path = Path(path)
    entries = _part_entries(path)
    try:
        meta = json.loads(entries[META_ENTRY])
    except ValueError as exc:
        raise PartError(f"{path}: unreadable part.json ({exc})") from None
    episodes = _batch_episodes(path, meta)
    tables: dict[str, pa.Table] = {}
    for name in PART_TABLES:
        recorded = (meta.get("tables") or {}).get(name) or {}
        table = _checked_table(path, name, entries[f"{name}.arrows"], recorded)
        counts = [entry["rows"].get(name) for entry in episodes]
        if not all(isinstance(c, int) and c >= 0 for c in counts) or sum(counts) != table.num_rows \
                or table.num_rows != recorded.get("rows"):
            raise PartError(f"{path}: table {name} has {table.num_rows} rows, part.json says otherwise")
        owners = pa.array([entry["episode_id"] for entry in episodes]).take(
            pa.array(np.repeat(np.arange(len(episodes)), counts)))
        if table.num_rows and not pc.all(pc.equal(table.column("episode_id"), owners)).as_py():
            raise PartError(f"{path}: table {name} holds rows of another episode")
        tables[name] = table
    parts, offsets = [], dict.fromkeys(PART_TABLES, 0)
    for entry in episodes:
        own = {}
        for name in PART_TABLES:
            own[name] = tables[name].slice(offsets[name], entry["rows"][name])
            offsets[name] += entry["rows"][name]
        if own["roads"].num_rows != int(entry["summary"].get("junctions", -1)) + 1:
            raise PartError(f"{path}: {own['roads'].num_rows} roads for {entry['summary'].get('junctions')} "
                            f"junctions in episode {entry['episode_id']}")
        parts.append(Part(episode_id=entry["episode_id"], task=entry["task"], summary=entry["summary"],
                          tables=own))
    return parts


def part_archive(meta: dict, blobs: dict[str, bytes]) -> bytes:
    """A part's zip, one format for an episode's part and a batch's: the metadata, each table's
    Arrow stream, and the checksum over both (fixed entry dates, so equal parts are equal bytes)."""
    meta_bytes = json.dumps(meta, sort_keys=True).encode()
    checksum = hashlib.sha256(meta_bytes)
    for name in PART_TABLES:
        checksum.update(blobs[name])
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as archive:
        entries = [(META_ENTRY, meta_bytes), *((f"{name}.arrows", blobs[name]) for name in PART_TABLES),
                   (CHECKSUM_ENTRY, checksum.hexdigest().encode())]
        for entry, data in entries:
            archive.writestr(zipfile.ZipInfo(entry, date_time=ZIP_DATE), data)
    return buffer.getvalue()


def _checked_table(path: Path, name: str, blob: bytes, recorded: dict) -> pa.Table:
    """A part's table `name` read from its Arrow stream: its recorded SHA-256 and its schema checked
    (an episode's part and a batch's alike)."""
    if recorded.get("sha256") != hashlib.sha256(blob).hexdigest():
        raise PartError(f"{path}: table {name} does not match its SHA-256")
    try:
        table = with_added_columns(pa.ipc.open_stream(blob).read_all(), PART_TABLES[name],
                                   ADDED_COLUMNS.get(name, ()))   # a part written before them
        return check_table(table, PART_TABLES[name], f"{path.name}:{name}")
    except (pa.ArrowException, SchemaError, ValueError) as exc:
        raise PartError(f"{path}: table {name}: {exc}") from None
