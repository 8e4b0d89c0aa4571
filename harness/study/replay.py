"""Replaying one episode of a finished study: the same config, seeds and population draws, checked.

`replay_episode(study_dir, episode_id)` rebuilds the study's config from its manifest (its inputs
are the study directory's own copies, harness/study/inputs.py, so a copied directory replays), refuses a
study whose inputs or code differ from what is installed now (the stored inputs' hashes, or for a
study made before they were stored the config's content hash; the versions of trustroute and of
the packages the episodes depend on), re-runs the planned episode
through the same function the study runner uses (runner.run_planned_episode), and compares the
episode's replayed tables with the logged ones row by row, column by column (roads, kinematics,
incidents: TABLE_COLUMNS), then its summary row (EPISODE_COLUMNS). Any difference is an InputError
(one line, exit 2) naming the table, the first row and the column that differ. A manifest that
stored its inputs before it recorded its config's SHA-256 has a config no hash checks: the replay
says so (inputs.unchecked_config) rather than passing over it.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from trustroute.app.engines import ENGINES
from trustroute.core.dataset import BELIEF_COLUMNS, EPISODE_ROWS, EPISODES_SCHEMA, TABLES, frame_from_table
from trustroute.core.errors import InputError
from trustroute.core.output_files import check_output_file, move_into_place, temp_path
from trustroute.core.wording import shown_value
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.context import study_context
from trustroute.harness.study.manifest import MANIFEST_FILE, episode_row, package_versions
from trustroute.harness.study.plan import EpisodeTask, participant_types, plan_episodes

if TYPE_CHECKING:
    from trustroute.harness.simulation.episode import EpisodeRecord

# The logged columns a replay reproduces, compared on every row of the episode's tables (EPISODE_ROWS:
# roads, kinematics, incidents) and in its summary row: exactly (the same code, seeds and SUMO give
# the same floats), but the beliefs (dataset.BELIEF_COLUMNS), floats after many Bayes updates, to
# REPLAYED_BELIEF_TOLERANCE. Not compared: `episode_id` (the rows are the episode's) and
# `wall_seconds` (the machine's time, never the same).
REPLAYED_BELIEF_TOLERANCE = 1e-12
TABLE_COLUMNS: dict[str, tuple[str, ...]] = {
    name: tuple(column for column in TABLES[name][1].names if column != "episode_id")
    for name in EPISODE_ROWS}
# The column that orders an episode's rows in each table, as the episode wrote them.
ROW_ORDER: dict[str, str] = {"roads": "index", "kinematics": "time", "incidents": "index"}
EPISODE_COLUMNS: tuple[str, ...] = tuple(name for name in EPISODES_SCHEMA.names
                                         if name not in ("episode_id", "wall_seconds"))
# Packages whose version changes what an episode does: a different one means different code.
EPISODE_PACKAGES: tuple[str, ...] = ("trustroute", "numpy", "scipy", "eclipse-sumo", "libsumo", "sumolib")


@dataclass(frozen=True, eq=False)
class Replay:
    task: EpisodeTask
    config: StudyConfig
    record: EpisodeRecord  # the replayed episode
    logged_roads: pd.DataFrame
    rrd_path: Path | None
    warnings: tuple[str, ...] = ()   # what the replay could not check (one line each)


def study_config_from_manifest(study_dir: Path, manifest: dict | None = None) -> tuple[StudyConfig, dict]:
    """The StudyConfig a study was run with (from manifest.json, or `manifest` as read), and the
    manifest."""
    from trustroute.core.dataset import CARLA_LOGS_ENGINE, read_manifest
    from trustroute.harness.study.inputs import relocated_config

    path = Path(study_dir) / MANIFEST_FILE
    manifest = read_manifest(Path(study_dir)) if manifest is None else manifest
    if manifest.get("engine") == CARLA_LOGS_ENGINE:   # no config: people drove it, in CARLA
        raise InputError(str(path), "engine",
                         "a study imported from CARLA logs has no study config to re-run it with",
                         f"read it with `trustroute analyze {study_dir}`; its ticks are in ticks.parquet")
    data = relocated_config(dict(manifest.get("config") or {}), Path(study_dir))
    known = {f.name for f in fields(StudyConfig)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(
            str(path),
            f"config.{unknown[0]}",
            f"the study was made by a different trustroute (unknown config key {unknown[0]!r})",
            "replay it with the trustroute that made it",
        )
    for key in ("specs", "conditions", "record", "routes", "live_inputs"):
        if key in data and data[key] is not None:
            data[key] = tuple(data[key])
    try:
        config = StudyConfig(**data)
    except TypeError as exc:
        raise InputError(
            str(path),
            "config",
            f"the study's config cannot be rebuilt ({exc})",
            "replay it with the trustroute that made it",
        ) from None
    return config, manifest


def check_same_code(manifest: dict, config: StudyConfig, study_dir: Path) -> str | None:
    """The installed code and the study's inputs are those the study was made with, or InputError;
    returns the warning line when the manifest's config has no recorded hash to check
    (inputs.unchecked_config), else None."""
    logged = manifest.get("packages", {})
    installed = package_versions()
    for name in EPISODE_PACKAGES:
        if name in logged and logged[name] != installed.get(name):
            raise InputError(
                str(Path(study_dir) / MANIFEST_FILE),
                f"packages.{name}",
                f"the study was made with {name} {logged[name]}, this is {installed.get(name)}, "
                "so a replay cannot reproduce it",
                f"install {name}=={logged[name]} to replay it",
            )
    if manifest.get("inputs"):
        # the study carries its inputs (harness/study/inputs.py): they are checked by their hashes,
        # wherever the directory lies (the config hash covers the paths it was run with)
        from trustroute.harness.study.inputs import unchecked_config, verify_inputs

        verify_inputs(manifest, study_dir)
        return unchecked_config(manifest, study_dir)
    for path in (
        *config.specs,
        config.town,
        config.driver_model,
        *(c for c in config.conditions if c not in ("aware", "free")),
    ):
        if path and not Path(path).is_file():
            raise InputError(
                str(study_dir),
                "config",
                f"the study's input {path} no longer exists",
                "replay it where the study was made",
            )
    if manifest.get("config_hash") != config.content_hash:
        raise InputError(
            str(Path(study_dir) / MANIFEST_FILE),
            "config_hash",
            "the study's spec, town, driver model or policy files changed since it was run",
            "restore them (see the manifest's config) or rerun the study",
        )
    return None


def logged_tables(study_dir: Path, episode_id: str, engine: str) -> dict[str, pa.Table]:
    """The episode's rows of each table of EPISODE_ROWS in ROW_ORDER, read through
    trustroute.core.dataset (checked); a study whose engine drives no SUMO logs no kinematics."""
    from trustroute.core.dataset import read_incidents_table, read_study_table

    study_dir = Path(study_dir)
    tables = {"roads": read_study_table(study_dir, "roads"),
              "kinematics": (read_study_table(study_dir, "kinematics") if ENGINES[engine].drives_sumo
                             else TABLES["kinematics"][1].empty_table()),
              "incidents": read_incidents_table(study_dir)}
    return {name: _episode_rows(tables[name], episode_id, name) for name in EPISODE_ROWS}


def _episode_rows(table: pa.Table, episode_id: str, name: str) -> pa.Table:
    rows = table.filter(pc.equal(table.column("episode_id"), episode_id))
    return rows.sort_by(ROW_ORDER[name])   # a stable sort: rows of one key keep the file's order


def _missing(value: object) -> bool:
    """Null, NaN, and the -1 that older studies wrote for "no report", all mean missing."""
    if value is None or value is pd.NA:
        return True
    if isinstance(value, (float, np.floating)):
        return math.isnan(value)
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)) and value == -1


# A table value as `to_pylist` gives it (ints and bools are floats to the type checker).
Cell = str | float | None


def _equal(a: Cell, b: Cell) -> bool:
    if _missing(a) or _missing(b) or a is None or b is None:   # None is missing
        return _missing(a) and _missing(b)
    if isinstance(a, (float, np.floating)) or isinstance(b, (float, np.floating)):
        return float(a) == float(b)
    return bool(a == b)


def _same(belief: bool, a: object, b: object) -> bool:
    if belief:
        return bool(np.allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                                rtol=0, atol=REPLAYED_BELIEF_TOLERANCE))
    return _equal(a, b)  # type: ignore[arg-type]


def _first_difference(name: str, logged: pa.Table, replayed: pa.Table
                      ) -> tuple[int, str, object, object] | None:
    """(row, column, logged value, replayed value) of the first difference between the rows two
    tables of `name` have in common, row by row and column by column of TABLE_COLUMNS, or None."""
    columns = list(TABLE_COLUMNS[name])
    logged, replayed = logged.select(columns), replayed.select(columns)
    if logged.equals(replayed):   # identical (NaN aside): no need to look at each value
        return None
    beliefs = BELIEF_COLUMNS.get(name, ())
    values = {column: (logged.column(column).to_pylist(), replayed.column(column).to_pylist())
              for column in columns}
    for i in range(min(logged.num_rows, replayed.num_rows)):
        for column in columns:
            a, b = values[column][0][i], values[column][1][i]
            if not _same(column in beliefs, a, b):
                return i, column, a, b
    return None


def compare_table(name: str, logged: pa.Table, replayed: pa.Table) -> str | None:
    """The first difference between the episode's logged rows of the table `name` (a key of
    TABLE_COLUMNS) and its replayed ones, as the words of the one-line error, or None when they agree."""
    file_name = TABLES[name][0]
    difference = _first_difference(name, logged, replayed)
    if logged.num_rows != replayed.num_rows:
        first = difference[0] if difference is not None else min(logged.num_rows, replayed.num_rows)
        if name == "roads":
            return (f"the replay drove {replayed.num_rows} roads, the log has {logged.num_rows} "
                    f"(first difference at road {first})")
        return (f"{file_name}: the replay has {replayed.num_rows} rows of the episode, the log "
                f"{logged.num_rows} (first difference at row {first})")
    if difference is None:
        return None
    row, column, a, b = difference
    shown = "differs" if column in BELIEF_COLUMNS.get(name, ()) else f"logged {a!r}, replayed {b!r}"
    return f"road {row} {column}: {shown}" if name == "roads" else f"{file_name} row {row} {column}: {shown}"


def compare_tables(logged: dict[str, pa.Table], replayed: EpisodeRecord) -> str | None:
    """The first difference between the logged tables of the episode (`logged_tables`) and the
    replayed ones, table by table in EPISODE_ROWS' order (roads first: another route explains
    every later difference), or None."""
    tables = replayed.tables()
    for name in EPISODE_ROWS:
        difference = compare_table(name, logged[name], tables[name])
        if difference is not None:
            return difference
    return None


def compare_episode(logged: dict, replayed: dict) -> str | None:
    """The first column of EPISODE_COLUMNS where the episode's logged summary row and the
    replayed one differ, or None when they agree."""
    for column in EPISODE_COLUMNS:
        a, b = logged.get(column), replayed.get(column)
        if not _equal(a, b):
            return f"episodes.parquet {column}: logged {a!r}, replayed {b!r}"
    return None


def logged_episode(study_dir: Path, episode_id: str) -> dict:
    from trustroute.core.dataset import read_episodes

    episodes = read_episodes(Path(study_dir))
    rows = episodes[episodes["episode_id"] == episode_id].to_dict("records")
    return rows[0] if rows else {}


def replayed_episode(config: StudyConfig, task: EpisodeTask, record: EpisodeRecord) -> dict:
    """The episodes-table row the study would have written for the replayed episode."""
    return episode_row(task, record.summary, record.tables(), participant_types(config))


def find_task(config: StudyConfig, episode_id: str, study_dir: Path) -> EpisodeTask:
    tasks = plan_episodes(config)
    for task in tasks:
        if task.episode_id == episode_id:
            return task
    raise InputError(
        str(study_dir),
        "EPISODE_ID",
        f"{shown_value(episode_id)} is not an episode of this study",
        f"pass one of its ids, e.g. {tasks[0].episode_id!r} (see episodes.parquet)",
    )


def replay_episode(
    study_dir: Path, episode_id: str, rrd_path: Path | None = None, gui: bool = False,
    check_code: bool = True, warn: Callable[[str], None] | None = None,
) -> Replay:
    """Re-run `episode_id` of the study in `study_dir`; InputError if it differs from the log.
    What the replay cannot check is a line of Replay.warnings, handed to `warn` (when given) before
    the episode runs, so it is said even when the replay then fails."""
    from trustroute.harness.study.runner import run_planned_episode

    study_dir = Path(study_dir)
    if rrd_path is not None:
        check_output_file(rrd_path, "--rrd", "Rerun recording", suffix=".rrd")
    config, manifest = study_config_from_manifest(study_dir)
    warning = check_same_code(manifest, config, study_dir) if check_code else None
    warnings = () if warning is None else (warning,)
    if warn is not None:
        for line in warnings:
            warn(line)
    task = find_task(config, episode_id, study_dir)
    logged = logged_tables(study_dir, episode_id, config.engine)
    if logged["roads"].num_rows == 0:
        raise InputError(
            str(study_dir),
            episode_id,
            "the episode has no logged roads (it failed or never ran)",
            "pick a finished episode (see episodes.parquet)",
        )
    if (rrd_path is not None or gui) and not ENGINES[config.engine].records:
        raise InputError(
            "--rrd" if rrd_path is not None else "--gui",
            "",
            f"the study ran the {config.engine} engine, which has no SUMO scene to record or show",
            'replay without --rrd/--gui, or rerun the study with engine = "sumo"',
        )
    sumo_config = None
    if gui:
        from trustroute.harness.simulation.sumo_start import SumoConfig, check_display

        check_display()
        sumo_config = SumoConfig(gui=True)
    # the recording goes to a temporary file, moved into place only once the replay matches the
    # log: a failed replay leaves an existing recording as it was and creates none
    temp = None if rrd_path is None else temp_path(Path(rrd_path))
    try:
        record = run_planned_episode(study_context(config), task, rrd_path=temp, sumo_config=sumo_config)
        difference = compare_tables(logged, record) or compare_episode(
            logged_episode(study_dir, episode_id), replayed_episode(config, task, record))
        if difference is not None:
            raise not_reproduced(study_dir, episode_id, manifest, difference)
        if temp is not None and rrd_path is not None:
            move_into_place(temp, Path(rrd_path), "recording")
    finally:
        if temp is not None:
            with contextlib.suppress(OSError):
                temp.unlink()
    return Replay(task=task, config=config, record=record, logged_roads=frame_from_table(logged["roads"]),
                  rrd_path=rrd_path, warnings=warnings)


def not_reproduced(study_dir: Path, episode_id: str, manifest: dict, difference: str) -> InputError:
    from trustroute.harness.study.manifest import git_revision

    made, now = manifest.get("git_revision", "unknown"), git_revision()
    if made != now:
        difference += f" (the study was made at git {made}, this is {now})"
    return InputError(
        str(study_dir),
        episode_id,
        f"the replay does not reproduce the log: {difference}",
        "replay with the code and packages the study was made with (see its manifest)",
    )
