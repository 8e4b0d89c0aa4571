"""Where a study is resumed: the study directory is checked to be new, empty or this study's (and
is marked as its own before anything else is written in it), and the episodes that already have a
valid part are found so a rerun skips them. A part that fails its checksum, or that another plan
wrote, is moved to damaged/ and its episode runs again; temporary files a killed run left are
removed. Used by `trustroute study` and the API's `run_study` (runner.py), `trustroute live` and
consolidation (manifest.py)."""

from __future__ import annotations

import json
import os
import zipfile
from dataclasses import asdict, fields
from pathlib import Path

from trustroute.core.dataset import (
    DAMAGED_DIR,
    LOCK_FILE,
    MANIFEST_FILE,
    PART_FOLDERS,
    PLOTS_DIR,
    STUDY_FILE,
    TABLES,
    read_manifest,
)
from trustroute.core.errors import InputError
from trustroute.core.output_files import TEMP_PREFIX, atomic_create_bytes, atomic_write_text, temp_path
from trustroute.core.validation import read_json
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.inputs import INPUTS_DIR
from trustroute.harness.study.parts import (
    Part,
    PartError,
    batch_part_paths,
    part_path,
    read_batch_part,
    read_part,
)
from trustroute.harness.study.plan import EpisodeTask


def study_files(study_dir: Path) -> list[str]:
    """The names of a study's own files that `study_dir` holds: its manifest, a table, a part, a
    failure or a damaged part. A run or an import writes over them only when they are the same
    study's; a new or empty directory, or one holding only the mark and the lock, holds none."""
    study_dir = Path(study_dir)
    names = [MANIFEST_FILE, *(file_name for file_name, _ in TABLES.values())]
    found = [name for name in names if (study_dir / name).exists()]
    for folder in (*PART_FOLDERS, DAMAGED_DIR):
        try:
            if (study_dir / folder).is_dir() and any((study_dir / folder).iterdir()):
                found.append(f"{folder}/")
        except OSError:   # an unreadable folder may hold anything
            found.append(f"{folder}/")
    return found


def recorded_config_hash(study_dir: Path, config_hash: str) -> str | None:
    """The config hash the study directory is marked with (None: new, empty, or a study without a
    readable mark whose manifest names this config); InputError when it holds a study with another
    config, holds a study's files (`study_files`) without a readable mark and its manifest does not
    name this config, or holds anything else without being a study (`check_own_folder`). Reads
    only: a refused directory is left as it was, so callers check it before marking it."""
    study_dir = Path(study_dir)
    marker = study_dir / STUDY_FILE
    recorded = _marked_hash(marker)
    if recorded is None:
        _check_unmarked(study_dir, config_hash, "missing" if not marker.exists() else "unreadable")
        return None
    if recorded != config_hash:
        raise InputError(
            str(study_dir),
            STUDY_FILE,
            "the directory holds a study with a different config (hash mismatch)",
            "pass another --out, or delete the directory to start over",
        )
    return recorded


def _marked_hash(marker: Path) -> str | None:
    """The config hash of a study mark; None when there is none or it cannot be read."""
    if not (marker.exists() or marker.is_symlink()):
        return None
    try:
        recorded = read_json(marker, "study marker")
    except InputError:
        return None
    value = recorded.get("config_hash") if isinstance(recorded, dict) else None
    return value if isinstance(value, str) else None


def _check_unmarked(study_dir: Path, config_hash: str, state: str) -> None:
    """A directory without a readable mark is this study's to write when it is new or empty
    (`check_own_folder`), or when its manifest names this config (a resume: the mark is written
    again)."""
    found = study_files(study_dir)
    if not found:
        check_own_folder(study_dir)
        return
    try:
        recorded = read_manifest(study_dir).get("config_hash")
    except InputError:
        recorded = None
    if recorded == config_hash:
        return
    raise InputError(
        str(study_dir),
        STUDY_FILE,
        f"{state}, and the directory holds a study ({', '.join(found[:3])}) whose manifest does not "
        "name this config",
        f"pass another --out, or restore {STUDY_FILE} from a backup to resume that study",
    )


# The start of the mark's temporary files' names (`temp_path`: the writer's pid follows)
MARK_TEMP = temp_path(Path(STUDY_FILE)).name.rsplit(".", 1)[0] + "."
# Files a desktop writes into any folder it shows (macOS Finder's, Windows Explorer's) and git's
# placeholder of an empty folder: a folder holding only these is empty to the person who made it
DESKTOP_FILES = frozenset({".DS_Store", "Thumbs.db", "desktop.ini", ".gitkeep"})


def check_own_folder(study_dir: Path) -> None:
    """The study directory is new, empty, or a study's (its mark readable, or a study's files in
    it): a folder of other files (a home folder, another program's data) is refused, not written
    into. The lock file, a mark's temporary file (a run killed while marking) and DESKTOP_FILES
    count as empty. Reads only."""
    study_dir = Path(study_dir)
    if not study_dir.is_dir() or _marked_hash(study_dir / STUDY_FILE) is not None or study_files(study_dir):
        return
    try:
        names = sorted(entry.name for entry in study_dir.iterdir())
    except OSError as exc:
        raise InputError(str(study_dir), "--out", f"cannot list the folder ({exc.strerror})",
                         "pass a readable folder, or a new one, to --out") from None
    others = [name for name in names
              if name != LOCK_FILE and not name.startswith(MARK_TEMP) and name not in DESKTOP_FILES]
    if others:
        raise InputError(str(study_dir), "--out",
                         f"the folder holds files that are not a study's ({', '.join(others[:3])}"
                         f"{', ...' if len(others) > 3 else ''})",
                         f"pass a new or empty folder to --out, e.g. {study_dir / 'study'}")


def mark_study_dir(study_dir: Path, config: StudyConfig, config_hash: str) -> None:
    """Mark the study directory as this study's before anything else is written in it (the folder
    made, then STUDY_FILE, atomically), or InputError as `recorded_config_hash` refuses it: so a
    run killed at any moment leaves a folder its rerun resumes. Another run marking it at the same
    moment is seen: one mark is written, and the run of another config is refused."""
    if recorded_config_hash(study_dir, config_hash) == config_hash:
        return
    marker = Path(study_dir) / STUDY_FILE
    text = json.dumps({"config_hash": config_hash, "config": asdict(config)}, indent=1, default=str)
    fix = "pass a writable --out"
    if marker.exists() or marker.is_symlink():   # unreadable, and the manifest names this config
        atomic_write_text(marker, text, "study marker", fix)
    elif not atomic_create_bytes(marker, text.encode(), "study marker", fix):
        mark_study_dir(study_dir, config, config_hash)   # marked meanwhile: this config's, or refused


# The folders a study writes in: a file in the place of one would fail every episode (or the
# consolidation) with the cause named only in each episode's failure.
STUDY_FOLDERS: tuple[str, ...] = (*PART_FOLDERS, DAMAGED_DIR, INPUTS_DIR, PLOTS_DIR)


def check_study_folders(study_dir: Path) -> None:
    """Each folder the study writes in is a folder where it exists; InputError naming the first
    that is not. Reads only, like `recorded_config_hash`."""
    for name in STUDY_FOLDERS:
        path = Path(study_dir) / name
        if (path.exists() or path.is_symlink()) and not path.is_dir():
            raise InputError(str(study_dir), name, f"not a folder (the study writes its {name} in it)",
                             f"move {path} aside, or pass another --out")


def quarantine_part(study_dir: Path, episode_id: str) -> None:
    """Move a part that failed verification to damaged/ (kept for inspection, out of the way)."""
    path = part_path(study_dir, episode_id)
    target = Path(study_dir) / DAMAGED_DIR / path.name
    target.parent.mkdir(parents=True, exist_ok=True)
    os.replace(path, target)


def quarantine_batch(study_dir: Path, path: Path) -> None:
    """Move a batch part that failed verification to damaged/ (all its episodes run again)."""
    target = Path(study_dir) / DAMAGED_DIR / path.name
    target.parent.mkdir(parents=True, exist_ok=True)
    os.replace(path, target)


def read_parts(study_dir: Path, tasks: list[EpisodeTask]) -> tuple[dict[str, Part], list[str]]:
    """(the verified part of every planned episode that has one, by episode id; the planned episodes
    whose part was damaged or written for another plan, moved aside). Batch parts first, then the
    episodes' own parts; an episode is taken once wherever it is stored, so no row is duplicated."""
    study_dir = Path(study_dir)
    planned = {task.episode_id: task for task in tasks}
    found: dict[str, Part] = {}
    damaged: list[str] = []
    for path in batch_part_paths(study_dir):
        try:
            batch = read_batch_part(path)
            if any(part.episode_id not in planned or _recorded(planned[part.episode_id]) != part.task
                   for part in batch):
                raise PartError(f"{path}: written for a different plan")
        except PartError:
            names = _batch_names(path)
            damaged += [name for name in names if name in planned]
            quarantine_batch(study_dir, path)
            continue
        for part in batch:
            found.setdefault(part.episode_id, part)
    for episode_id, task in planned.items():
        path = part_path(study_dir, episode_id)
        if episode_id in found or not path.exists():
            continue
        try:
            part = read_part(path)
            if part.task != _recorded(task):
                raise PartError(f"{path}: written for a different plan")
        except PartError:
            damaged.append(episode_id)
            quarantine_part(study_dir, episode_id)
            continue
        found[episode_id] = part
    # a damaged batch names what it claims to hold: only episodes no valid part holds are damaged
    return found, list(dict.fromkeys(name for name in damaged if name not in found))


def _recorded(task: EpisodeTask) -> dict:
    """The task as a part records it (JSON: the seed's spawn key a list)."""
    recorded = {name: getattr(task, name) for name in TASK_FIELDS}
    return {**recorded, "driver_entropy": list(task.driver_entropy)}


TASK_FIELDS = tuple(field.name for field in fields(EpisodeTask))


def _batch_names(path: Path) -> list[str]:
    """The episode ids a (possibly damaged) batch part claims, as far as they can be read."""

    try:
        with zipfile.ZipFile(path) as archive:
            meta = json.loads(archive.read("part.json"))
        return [str(entry["episode_id"]) for entry in meta["episodes"]]
    except Exception:  # a damaged part may fail in any way: its episodes show as missing instead
        return []


def finished_episodes(study_dir: Path, tasks: list[EpisodeTask]) -> tuple[set[str], list[str]]:
    """(episode ids with a valid part, episode ids whose part was damaged and has been moved aside).

    Also removes temporary files a killed run left behind. A part whose recorded task differs
    from the plan (another config wrote it) counts as damaged.
    """
    study_dir = Path(study_dir)
    for folder in PART_FOLDERS:
        for temp in (study_dir / folder).glob(f"{TEMP_PREFIX}*"):
            temp.unlink(missing_ok=True)
    found, damaged = read_parts(study_dir, tasks)
    return set(found), damaged
