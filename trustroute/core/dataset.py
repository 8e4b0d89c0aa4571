"""The study dataset, defined once: file names, Arrow schemas of its four tables, manifest keys.

The harness writes through this module (harness/study/parts.py, harness/study/manifest.py,
`trustroute run --out`) and analysis reads through it (`read_study_table`, and one reader per
table on it, each checking the schema and the values). Every column and file is documented in
docs/dataset.md; change both together.

Missing values are nulls (never -1, "" or a NaN standing for "none"): a report not given, the
action after the last road, the performance of the start road, sim times of the model engine.
The start road (row 0 of an episode's roads) has incident `none` and no observation.

In pandas (`frame_from_table`), nullable integer columns are `Int64` and nullable booleans are
`boolean` (so a null stays a null); nullable floats are float64 with NaN; strings are pandas'
string dtype with missing values for nulls.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from trustroute.core import package as packages
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_bytes
from trustroute.core.validation import first_non_belief, read_input_bytes, read_json
from trustroute.core.wording import shown_value

# -- files of a study directory ------------------------------------------------------------------
REBUILD_FIX = "rerun `trustroute study` on this directory to rebuild it"   # a damaged file's fix
STUDY_FILE = "study.json"            # the config hash and config of the study in this directory
LOCK_FILE = "study.lock"             # held (fcntl.flock) by the run using the directory; names it
MANIFEST_FILE = "manifest.json"
CARLA_LOGS_ENGINE = "carla-logs"   # the manifest's engine of a study imported from the authors' CARLA logs
# where logs lie in a folder that is not a study (a checkout of the authors' repository keeps its
# CSVs two folders down, trust_level_record/driver_N/): `import carla-logs` makes it one
LOG_PATTERNS = ("*.csv", "*/*.csv", "*/*/*.csv")
EPISODES_FILE = "episodes.parquet"
ROADS_FILE = "roads.parquet"
KINEMATICS_FILE = "kinematics.parquet"  # SUMO engine only
INCIDENTS_FILE = "incidents.parquet"    # SUMO engine only, when some road had an incident or takeover
ATTEMPTS_FILE = "attempts.parquet"      # live studies: every attempt of every drive, in the order run
QUESTIONNAIRES_FILE = "questionnaires.parquet"  # live studies with [questionnaires]: every answer
SUMMARY_FILE = "summary.json"        # `trustroute run --out DIR`: the episode summary
REPORT_MARKDOWN_FILE = "report.md"
REPORT_HTML_FILE = "report.html"
PLOTS_DIR = "plots"
# Per-episode files while a study runs (one file per episode id in each folder).
PARTS_DIR = "parts"                  # <episode_id>.zip: every table of the episode + checksum
FAILURES_DIR = "failures"            # <episode_id>.json: every attempt's error of a failed episode
DAMAGED_DIR = "damaged"              # parts found damaged, foreign or of another format, moved aside
PART_FOLDERS: tuple[str, ...] = (PARTS_DIR, FAILURES_DIR)
PART_SUFFIX = ".zip"                 # the part format: harness/study/parts.py
MAX_TABLE_BYTES = 8 * 1024**3  # a table is read whole; a larger file is not one of ours
# Bump when a table's columns or their meaning change: parts of another format are not resumed
# (they are moved to damaged/ and their episodes re-run), so a study never mixes two formats.
DATASET_FORMAT = "2"   # 2: missing values are nulls (1 used -1 and "")


def part_path(study_dir: Path, episode_id: str) -> Path:
    return Path(study_dir) / PARTS_DIR / f"{episode_id}{PART_SUFFIX}"


def failure_path(study_dir: Path, episode_id: str) -> Path:
    return Path(study_dir) / FAILURES_DIR / f"{episode_id}.json"


# -- schemas ----------------------------------------------------------------------------------------
def _field(name: str, kind: pa.DataType, nullable: bool = False) -> pa.Field:
    return pa.field(name, kind, nullable=nullable)


def required_schema(**columns: pa.DataType) -> pa.Schema:
    """A schema of non-nullable columns, in the order given (for tables beside the dataset's)."""
    return pa.schema([_field(name, kind) for name, kind in columns.items()])


BELIEF = pa.list_(pa.float64())

ROADS_SCHEMA = pa.schema([
    _field("episode_id", pa.string()),
    _field("index", pa.int64()),                      # position in the episode; 0 = the start road
    _field("directed_road", pa.string()),
    _field("action", pa.string(), nullable=True),     # junction chosen here; null on the last road
    _field("incident", pa.string()),                  # "none" on the start road
    _field("takeover", pa.bool_(), nullable=True),    # null on the start road (no observation)
    _field("performance", pa.string(), nullable=True),  # "succ"/"fail"; null on the start road
    _field("trust_before", pa.int64(), nullable=True),  # true trust; null when unknown (real logs)
    _field("trust_after", pa.int64(), nullable=True),
    _field("reported_trust", pa.int64(), nullable=True),  # null: no report on this road
    _field("belief_before", BELIEF),
    _field("belief_after", BELIEF),
    _field("dfa_state", pa.int64()),
    _field("fallback", pa.bool_()),
    _field("sim_time_in", pa.float64(), nullable=True),   # null in the model engine
    _field("sim_time_out", pa.float64(), nullable=True),  # null on the last road and in the model engine
])

KINEMATICS_SCHEMA = pa.schema([
    _field("episode_id", pa.string()),
    _field("time", pa.float64()),
    _field("x", pa.float64()),
    _field("y", pa.float64()),
    _field("speed", pa.float64()),
    _field("lane", pa.string()),
    _field("mode", pa.string()),
])

INCIDENTS_SCHEMA = pa.schema([
    _field("episode_id", pa.string()),
    _field("index", pa.int64()),
    _field("directed_road", pa.string()),
    _field("incident", pa.string()),
    _field("sumo_ids", pa.string(), nullable=True),        # comma-separated; null: no SUMO objects
    _field("injected_time", pa.float64(), nullable=True),
    _field("in_view_time", pa.float64(), nullable=True),
    _field("x", pa.float64(), nullable=True),
    _field("y", pa.float64(), nullable=True),
    _field("passed_time", pa.float64(), nullable=True),
    _field("removed_time", pa.float64(), nullable=True),
    _field("takeover", pa.bool_()),
    _field("takeover_start", pa.float64(), nullable=True),
    _field("takeover_end", pa.float64(), nullable=True),
    _field("performance", pa.string()),
    _field("min_ttc", pa.float64()),                        # inf: never within the TTC threshold
    _field("max_deceleration", pa.float64()),
    _field("collided", pa.bool_()),
    # Performance measures and the scene's draws (docs/scenes.md; harness/simulation/performance.py).
    _field("min_head_on_ttc", pa.float64()),                # inf: no oncoming vehicle that close
    _field("min_pedestrian_distance", pa.float64()),        # inf: no person on the crossing near the ego
    _field("time_lost", pa.float64()),                      # s against free driving, on autopilot
    _field("failed_measures", pa.string(), nullable=True),  # comma-separated; null: succ
    _field("scene", pa.string(), nullable=True),            # the drawn scene; null: no SUMO objects
    # Manual-driving measures of the takeover (harness/simulation/manual_measures.py): the reaction
    # wherever there was a takeover of an incident in view; the others only when a person drove by
    # wheel ([live] driving = "continuous"); null otherwise.
    _field("takeover_reaction", pa.float64(), nullable=True),      # s from in view to the takeover
    _field("lateral_sd", pa.float64(), nullable=True),             # m: SD of the lateral position
    _field("manual_min_ttc", pa.float64(), nullable=True),         # s; inf: nothing closing in its path
    _field("manual_max_deceleration", pa.float64(), nullable=True),  # m/s²
    _field("oncoming_seconds", pa.float64(), nullable=True),       # s in the oncoming lane
    _field("road_departures", pa.int64(), nullable=True),
    _field("collisions", pa.int64(), nullable=True),
])
MANUAL_MEASURES: tuple[str, ...] = (
    "takeover_reaction", "lateral_sd", "manual_min_ttc", "manual_max_deceleration", "oncoming_seconds",
    "road_departures", "collisions",
)

# The plan's columns, then the episode summary's (harness/simulation/episode_tracker.py), then report stats.
PLAN_COLUMNS: tuple[str, ...] = ("episode_id", "participant", "position", "spec", "condition", "seed")
SUMMARY_COLUMNS: tuple[str, ...] = (
    "satisfied", "junctions", "takeovers", "final_trust", "mean_trust", "end_reason",
    "fallback_fired", "sim_seconds", "wall_seconds",
)
EPISODES_SCHEMA = pa.schema([
    _field("episode_id", pa.string()),
    _field("participant", pa.int64()),
    _field("position", pa.int64()),
    _field("spec", pa.string()),
    _field("condition", pa.string()),
    _field("seed", pa.int64()),
    _field("satisfied", pa.bool_()),
    _field("junctions", pa.int64()),
    _field("takeovers", pa.int64()),
    _field("final_trust", pa.int64(), nullable=True),       # null when the true trust is unknown
    _field("mean_trust", pa.float64(), nullable=True),
    _field("end_reason", pa.string()),
    _field("fallback_fired", pa.bool_()),
    _field("sim_seconds", pa.float64(), nullable=True),     # null in the model engine
    _field("wall_seconds", pa.float64()),
    _field("mean_reported_trust", pa.float64(), nullable=True),  # null: no report in the episode
    _field("reports", pa.int64()),
    # The participant's true driver type ([drivers] population, docs/driver_type_studies.md); null
    # without one.
    _field("driver_type", pa.string(), nullable=True),
    # The episode's manual-driving measures over its takeovers (the incidents table's columns of
    # the same names, harness/simulation/manual_measures.py `episode_measures`); null without them.
    _field("mean_takeover_reaction", pa.float64(), nullable=True),   # s, mean over the takeovers
    _field("mean_lateral_sd", pa.float64(), nullable=True),          # m, mean over those by wheel
    _field("manual_min_ttc", pa.float64(), nullable=True),           # s, least
    _field("manual_max_deceleration", pa.float64(), nullable=True),  # m/s², largest
    _field("oncoming_seconds", pa.float64(), nullable=True),         # s, in all
    _field("road_departures", pa.int64(), nullable=True),
    _field("collisions", pa.int64(), nullable=True),
])
# Live studies (harness/live/attempts.py): one row per attempt of a drive (a trial or the warm-up),
# whatever its outcome; `run_position` is the place of a done trial in the order actually run.
ATTEMPT_OUTCOMES: tuple[str, ...] = ("started", "aborted", "failed", "incomplete", "done")
ATTEMPTS_SCHEMA = pa.schema([
    _field("participant", pa.int64()),
    _field("episode_id", pa.string()),
    _field("warm_up", pa.bool_()),
    _field("planned_position", pa.int64(), nullable=True),   # the plan's (Williams square); null: warm-up
    _field("attempt", pa.int64()),                           # 1, 2, ... of this drive
    _field("sequence", pa.int64()),                          # 1, 2, ... of the participant's attempts
    _field("run_position", pa.int64(), nullable=True),       # 0-based among their done trials; else null
    _field("started_utc", pa.string()),
    _field("ended_utc", pa.string(), nullable=True),         # null: still running, or the server stopped
    _field("outcome", pa.string()),                          # one of ATTEMPT_OUTCOMES
    _field("reason", pa.string(), nullable=True),            # why it was aborted, failed or incomplete
])

# Live studies with [questionnaires] (participants/questionnaires.py, harness/live/answers.py): one
# row per item answered.
QUESTIONNAIRE_PLACEMENTS: tuple[str, ...] = ("before", "after_each_trial", "end")
QUESTIONNAIRES_SCHEMA = pa.schema([
    _field("participant", pa.int64()),
    _field("episode_id", pa.string(), nullable=True),   # the trial it followed; null: before or end
    _field("placement", pa.string()),                   # one of QUESTIONNAIRE_PLACEMENTS
    _field("questionnaire", pa.string()),               # jian, nasa_tlx, or a file's name
    _field("item", pa.string()),
    _field("item_index", pa.int64()),                   # 0-based place in the questionnaire
    _field("value", pa.float64()),                      # as answered (not reversed)
    _field("reversed", pa.bool_()),                     # scored as scale_min + scale_max - value
    _field("scale_min", pa.float64()),
    _field("scale_max", pa.float64()),
    _field("answered_utc", pa.string()),
])

EPISODE_MANUAL_MEASURES: tuple[str, ...] = (
    "mean_takeover_reaction", "mean_lateral_sd", "manual_min_ttc", "manual_max_deceleration",
    "oncoming_seconds", "road_departures", "collisions",
)
# Nullable columns appended to a schema after studies were written without them: a file that ends
# before them reads with the columns all null (so datasets written without those columns still read).
ADDED_COLUMNS: dict[str, tuple[str, ...]] = {"episodes": ("driver_type", *EPISODE_MANUAL_MEASURES),
                                             "incidents": MANUAL_MEASURES}
END_REASONS: tuple[str, ...] = ("accepted", "rejected", "destination", "cap")

# Top-level keys of manifest.json (harness/study/manifest.py writes them; docs/dataset.md).
MANIFEST_KEYS: tuple[str, ...] = (
    "study", "config_path", "config", "config_hash", "engine", "created_utc", "git_revision",
    "packages", "command", "planned_episodes", "finished_episodes", "failed_episodes", "seeds",
    "files", "expected", "run", "inputs",
)
# Keys a manifest written before they existed lacks (its study stays readable).
MANIFEST_OPTIONAL_KEYS: tuple[str, ...] = ("inputs",)

TABLES: dict[str, tuple[str, pa.Schema]] = {
    "episodes": (EPISODES_FILE, EPISODES_SCHEMA),
    "roads": (ROADS_FILE, ROADS_SCHEMA),
    "kinematics": (KINEMATICS_FILE, KINEMATICS_SCHEMA),
    "incidents": (INCIDENTS_FILE, INCIDENTS_SCHEMA),
    "attempts": (ATTEMPTS_FILE, ATTEMPTS_SCHEMA),
    "questionnaires": (QUESTIONNAIRES_FILE, QUESTIONNAIRES_SCHEMA),
}


class SchemaError(ValueError):
    """A table whose columns, types or nulls differ from its schema."""


# -- conversions ---------------------------------------------------------------------------------
def table_from_frame(frame: pd.DataFrame, schema: pa.Schema) -> pa.Table:
    """`frame` as an Arrow table of `schema` (columns in schema order, NaN and None as nulls)."""
    missing = [name for name in schema.names if name not in frame.columns]
    if missing:
        raise SchemaError(f"missing column(s) {', '.join(missing)}")
    try:
        table = pa.Table.from_pandas(frame[list(schema.names)], schema=schema, preserve_index=False)
    except (pa.ArrowException, ValueError, TypeError) as exc:
        raise SchemaError(str(exc)) from None
    return check_table(table.replace_schema_metadata(None), schema)


def table_from_columns(columns: dict[str, list | object], schema: pa.Schema,
                       nan_as_null: bool = True) -> pa.Table:
    """Python lists (None for nulls) or numpy arrays per column as an Arrow table of `schema`; NaN
    is a null too unless `nan_as_null` is False. Each column is converted to its field's type, so
    only the nulls of the non-null fields are left to check (the episode loggers build three
    tables per episode through here)."""
    try:
        arrays = [pa.array(columns[f.name], type=f.type, from_pandas=nan_as_null) for f in schema]
    except KeyError as exc:
        raise SchemaError(f"missing column {exc.args[0]}") from None
    except (pa.ArrowException, TypeError, ValueError) as exc:
        raise SchemaError(str(exc)) from None
    return _check_required(pa.Table.from_arrays(arrays, schema=schema), schema, "table")


def table_from_rows(rows: list[dict], schema: pa.Schema) -> pa.Table:
    """Rows as dicts keyed by the schema's names (None or NaN for nulls; a key a row lacks is a
    null too) as an Arrow table of `schema`: one conversion through the schema's struct type
    instead of one per column, the cheap form for the few rows an episode logs per road."""
    try:
        table = pa.Table.from_struct_array(pa.array(rows, type=_layout(schema)[1], from_pandas=True))
    except (pa.ArrowException, TypeError, ValueError) as exc:
        raise SchemaError(str(exc)) from None
    return _check_required(table, schema, "table")


def _check_required(table: pa.Table, schema: pa.Schema, source: str) -> pa.Table:
    for i in _required_columns(schema):
        column = table.column(i)
        if column.null_count:
            raise SchemaError(f"{source}: column {schema.names[i]!r} has {column.null_count} null(s)")
    return table


def _layout_of(schema: pa.Schema) -> tuple[pa.Schema, pa.StructType, tuple[int, ...]]:
    """(schema, its struct type, indices of its non-null fields)."""
    return schema, pa.struct(list(schema)), tuple(i for i, f in enumerate(schema) if not f.nullable)


# The layouts of the dataset's own tables, computed here once with their schemas (module
# constants, alive as long as the process): a table is made and checked several times per episode,
# and listing a schema's fields costs pyarrow about 30 µs. Read-only, filled at import, never grown;
# another schema's layout is computed where its table is made.
_DATASET_LAYOUTS = MappingProxyType({id(schema): _layout_of(schema) for _, schema in TABLES.values()})


def _layout(schema: pa.Schema) -> tuple[pa.Schema, pa.StructType, tuple[int, ...]]:
    found = _DATASET_LAYOUTS.get(id(schema))
    return found if found is not None and found[0] is schema else _layout_of(schema)


def _required_columns(schema: pa.Schema) -> tuple[int, ...]:
    """Indices of the non-null fields of `schema`."""
    return _layout(schema)[2]


def check_table(table: pa.Table, schema: pa.Schema, source: str = "table") -> pa.Table:
    """`table` itself when its columns, types and nulls match `schema`; else SchemaError."""
    if table.schema.equals(schema):
        # Names, types and nullability are the schema's: only the nulls of non-null fields to check.
        return _check_required(table, schema, source)
    names = table.schema.names
    if names != schema.names:
        raise SchemaError(f"{source}: columns {names} differ from the schema's {schema.names}")
    for f in schema:
        column = table.column(f.name)
        if column.type != f.type:
            raise SchemaError(f"{source}: column {f.name!r} is {column.type}, expected {f.type}")
        if not f.nullable and column.null_count:
            raise SchemaError(f"{source}: column {f.name!r} has {column.null_count} null(s)")
    return table.cast(schema)


def frame_from_table(table: pa.Table) -> pd.DataFrame:
    """A dataset table in pandas, keeping nulls of integer and boolean columns (Int64, boolean)."""
    frame = table.to_pandas()
    for f in table.schema:
        if f.nullable and pa.types.is_integer(f.type):
            frame[f.name] = frame[f.name].astype("Int64")
        elif f.nullable and pa.types.is_boolean(f.type):
            frame[f.name] = frame[f.name].astype("boolean")
    return frame


def write_table(table: pa.Table, path: Path) -> Path:
    """Write a dataset table (already checked) as Parquet with page checksums, atomically (a full
    disk or a kill leaves the previous file or none, never part of one; trustroute.core.output_files)."""
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, write_page_checksum=True)
    return atomic_write_bytes(Path(path), sink.getvalue().to_pybytes(), f"dataset table {Path(path).name}",
                              "free disk space or pass a writable --out, then rerun")


# -- readers ---------------------------------------------------------------------------------------
def with_added_columns(table: pa.Table, schema: pa.Schema, added: tuple[str, ...]) -> pa.Table:
    """`table` with the trailing `added` columns of `schema` it lacks appended as nulls."""
    names = table.schema.names
    missing = [name for name in schema.names if name not in names]
    earlier = schema.names[:len(names)] == names and missing == list(added[len(added) - len(missing):])
    if not missing or not earlier:
        return table  # not an earlier form of this schema: check_table reports it
    for name in missing:
        table = table.append_column(schema.field(name), pa.nulls(table.num_rows, schema.field(name).type))
    return table


# -- values ----------------------------------------------------------------------------------------
# What a study's tables hold beyond their schemas (docs/dataset.md, "Values"), checked on every
# read, vectorised: a table of the right columns can still hold impossible values.
UNIQUE_ROWS: dict[str, tuple[str, ...]] = {"episodes": ("episode_id",), "roads": ("episode_id", "index")}
BELIEF_COLUMNS: dict[str, tuple[str, ...]] = {"roads": ("belief_before", "belief_after")}
# Columns of a trust level (null where nullable): checked against the study's driver model.
TRUST_COLUMNS: dict[str, tuple[str, ...]] = {"episodes": ("final_trust",),
                                             "roads": ("trust_before", "trust_after", "reported_trust")}
# Tables whose every row belongs to an episode of episodes.parquet.
EPISODE_ROWS: tuple[str, ...] = ("roads", "kinematics", "incidents")


def check_allowed(values: pd.Series, allowed: Iterable, source: str, column: str, what: str,
                  fix: str = REBUILD_FIX) -> None:
    """InputError at the first row of `values` (a table's column, in file order; nulls pass) whose
    value is not in `allowed`: "`column`, row N: VALUE is not `what`"."""
    outside = ~(values.isna() | values.isin(list(allowed))).to_numpy(dtype=bool)
    if outside.any():
        row = int(np.flatnonzero(outside)[0])
        value = values.iloc[row]
        raise InputError(source, f"{column}, row {row}", f"{shown_value(value)} is not {what}", fix)


def _check_unique(table: pa.Table, keys: tuple[str, ...], source: str, fix: str) -> None:
    repeated = table.select(list(keys)).to_pandas().duplicated().to_numpy(dtype=bool)
    if repeated.any():
        row = int(np.flatnonzero(repeated)[0])
        key = ", ".join(f"{k} {table.column(k)[row].as_py()!r}" for k in keys)
        raise InputError(source, f"{keys[-1]}, row {row}", f"a second row of {key}", fix)


def _check_beliefs(table: pa.Table, column: str, source: str, width: int | None, fix: str) -> None:
    """Every belief of `column` a probability vector of `width` entries (default: the first row's)."""
    beliefs = table.column(column).combine_chunks()
    lengths = pc.list_value_length(beliefs).to_numpy(zero_copy_only=False)
    if not lengths.size:
        return
    width = int(lengths[0]) if width is None else width
    wrong = np.flatnonzero(lengths != width)
    if wrong.size:
        row = int(wrong[0])
        raise InputError(source, f"{column}, row {row}", f"a belief of {lengths[row]} entries, not {width} "
                         "(one per trust level of the study's driver model)", fix)
    values = pc.list_flatten(beliefs).to_numpy(zero_copy_only=False).astype(float)
    found = first_non_belief(values.reshape(lengths.size, width))
    if found is not None:
        raise InputError(source, f"{column}, row {found[0]}", f"not a probability vector: {found[1]}", fix)


def check_values(table: pa.Table, name: str, source: str,
                 trust_levels: tuple[int, ...] | None = None, fix: str = REBUILD_FIX) -> None:
    """The values of the study table `name` (a key of TABLES) read from `source`, or InputError naming
    the column and first bad row (and `fix`): no two rows of one episode (one road of an episode),
    beliefs that are probability vectors of one length, and given the study driver model's
    `trust_levels`, every trust one of them (or null) and beliefs of one entry per level."""
    if name in UNIQUE_ROWS:
        _check_unique(table, UNIQUE_ROWS[name], source, fix)
    width = None if trust_levels is None else len(trust_levels)
    for column in BELIEF_COLUMNS.get(name, ()):
        _check_beliefs(table, column, source, width, fix)
    if trust_levels is None:
        return
    levels = ", ".join(str(level) for level in trust_levels)
    for column in TRUST_COLUMNS.get(name, ()):
        check_allowed(table.column(column).to_pandas().astype("Int64"), trust_levels, source, column,
                      f"a trust level of the study's driver model ({levels})", fix)


def read_table(path: Path, schema: pa.Schema | tuple[pa.Schema, ...], columns: list[str] | None = None,
               added: tuple[str, ...] = (), fix: str = REBUILD_FIX) -> pa.Table:
    """A dataset table file checked against its schema (of several: the one of its columns, its
    `added` columns missing at the end read as nulls, else the first); InputError naming the file
    when it is missing, or (with `fix`) unreadable or of another schema."""
    path = Path(path)
    if not path.exists():
        raise InputError(str(path), "", "no such dataset file",
                         "run `trustroute study CONFIG --out DIR` first (a rerun resumes and consolidates)")
    # Through the guarded reader: a FIFO or a device in place of a table must not block.
    data = read_input_bytes(path, "dataset table", MAX_TABLE_BYTES, fix=fix)
    try:
        table = pq.read_table(pa.BufferReader(data), page_checksum_verification=True)
        table = table.replace_schema_metadata(None)
        schemas = schema if isinstance(schema, tuple) else (schema,)
        filled = ((with_added_columns(table, s, added), s) for s in schemas)
        table, schema = next((pair for pair in filled if pair[0].schema.names == pair[1].names),
                             (table, schemas[0]))
        check_table(table, schema, path.name)
    except (OSError, pa.ArrowException, SchemaError) as exc:
        raise InputError(str(path), "schema" if isinstance(exc, SchemaError) else "",
                         f"cannot read the dataset table ({exc})", fix) from None
    return table.select(columns) if columns is not None else table


def read_study_table(study_dir: Path, name: str, columns: list[str] | None = None,
                     trust_levels: tuple[int, ...] | None = None, packaged: bool | None = None) -> pa.Table:
    """The table `name` (a key of TABLES) of a study directory or a package (`packaged`: whether it
    is one, `packages.is_package`, when the caller has asked): the one reader of a study's tables,
    checking the file against its schema (`read_table`; a package's as an export writes it), its
    values (`check_values`; trust levels given: those of the study's driver model) and that its rows
    belong to the study's episodes (of its episodes.parquet, if any: `trustroute run --out` writes none)."""
    packaged = packages.is_package(study_dir) if packaged is None else packaged
    tables = packages.tables_folder(study_dir, packaged)
    fix = packages.PACKAGE_TABLE_FIX if packaged else REBUILD_FIX
    schema = {table: packages.package_schemas(TABLES[table][1], table) if packaged else TABLES[table][1]
              for table in (name, "episodes")}
    path, episodes = tables / TABLES[name][0], tables / EPISODES_FILE
    table = read_table(path, schema[name], None, ADDED_COLUMNS.get(name, ()), fix)
    check_values(table, name, str(path), trust_levels, fix)
    if name in EPISODE_ROWS and episodes.exists():
        # the ids only: the episodes' own values are checked where the episodes are read
        known = read_table(episodes, schema["episodes"], ["episode_id"], ADDED_COLUMNS["episodes"], fix)
        check_allowed(table.column("episode_id").to_pandas(), known.column(0).combine_chunks().to_pylist(),
                      str(path), "episode_id", f"an episode of {EPISODES_FILE}", fix)
    return table.select(columns) if columns is not None else table


def _read(study_dir: Path, name: str, columns: list[str] | None,
          trust_levels: tuple[int, ...] | None = None) -> pd.DataFrame:
    return frame_from_table(read_study_table(study_dir, name, columns, trust_levels))


def read_episodes(study_dir: Path, columns: list[str] | None = None,
                  trust_levels: tuple[int, ...] | None = None) -> pd.DataFrame:
    """episodes.parquet of a consolidated study, checked (`read_study_table`)."""
    return _read(study_dir, "episodes", columns, trust_levels)


def read_roads(study_dir: Path, columns: list[str] | None = None,
               trust_levels: tuple[int, ...] | None = None) -> pd.DataFrame:
    """roads.parquet of a consolidated study (or of `trustroute run --out`), checked (`read_study_table`)."""
    return _read(study_dir, "roads", columns, trust_levels)


def read_kinematics(study_dir: Path, columns: list[str] | None = None) -> pd.DataFrame:
    """kinematics.parquet (SUMO engine), checked (`read_study_table`)."""
    return _read(study_dir, "kinematics", columns)


def read_incidents_table(study_dir: Path, columns: list[str] | None = None) -> pa.Table:
    """incidents.parquet (SUMO engine), checked (`read_study_table`); an empty table when a study
    directory or a package had no incident objects and no takeovers (the file is then not written)."""
    packaged = packages.is_package(study_dir)
    written = (packages.tables_folder(study_dir, packaged) / INCIDENTS_FILE).exists()
    if (packaged or (Path(study_dir) / MANIFEST_FILE).exists()) and not written:
        return INCIDENTS_SCHEMA.empty_table().select(columns or INCIDENTS_SCHEMA.names)
    return read_study_table(study_dir, "incidents", columns, packaged=packaged)


def read_incidents(study_dir: Path, columns: list[str] | None = None) -> pd.DataFrame:
    """incidents.parquet in pandas (`read_incidents_table`)."""
    return frame_from_table(read_incidents_table(study_dir, columns))


def read_attempts(study_dir: Path, columns: list[str] | None = None) -> pd.DataFrame:
    """attempts.parquet (live studies), checked against ATTEMPTS_SCHEMA."""
    return _read(study_dir, "attempts", columns)


def read_questionnaires(study_dir: Path, columns: list[str] | None = None) -> pd.DataFrame:
    """questionnaires.parquet (live studies with questionnaires), checked against QUESTIONNAIRES_SCHEMA."""
    return _read(study_dir, "questionnaires", columns)


def no_manifest_fix(study_dir: Path) -> str:
    """The fix for a folder without a manifest, by what it holds (`trustroute study` refuses live ones)."""
    marker = study_dir / STUDY_FILE
    try:
        recorded = read_json(marker, "study marker") if marker.is_file() else {}
    except InputError:   # a damaged marker: the general fix
        recorded = {}
    config = recorded.get("config") if isinstance(recorded, dict) else None
    if isinstance(config, dict) and config.get("engine") == "live":
        return ("serve it with `trustroute live CONFIG --out DIR`: the dataset and its manifest are written "
                "once a participant finishes an episode")
    if any(next(study_dir.glob(pattern), None) is not None for pattern in LOG_PATTERNS):
        return ("a folder of logs is read once imported: "
                f"`trustroute import carla-logs {study_dir} --out STUDY` (the authors' CARLA logs), "
                "then pass STUDY")
    return (packages.package_fix(study_dir)   # an export's package, no study
            or "run `trustroute study CONFIG --out DIR` first (a rerun resumes and consolidates)")


def check_study_dir(study_dir: Path) -> Path:
    """`study_dir` is a consolidated study's folder (it has a manifest), or InputError: checked
    before its lock is taken, so that a command refused a folder leaves nothing in it."""
    path = Path(study_dir) / MANIFEST_FILE
    if not Path(study_dir).is_dir():
        problem = "not a directory" if Path(study_dir).exists() else "no such directory"
        raise InputError(str(study_dir), "", problem,
                         "pass the folder a study, demo, live study or import wrote (their --out)")
    if not path.exists():
        raise InputError(str(study_dir), MANIFEST_FILE, "not a finished study directory (no manifest)",
                         no_manifest_fix(Path(study_dir)))
    return path


def read_manifest(study_dir: Path, package: bool = False) -> dict:
    """manifest.json of a study, every key of MANIFEST_KEYS; `package`: the manifest of a package
    whose checksums the caller found matching (`packages.verify_package`)."""
    path = Path(study_dir) / packages.PACKAGE_MANIFEST_FILE if package else check_study_dir(study_dir)
    fix = packages.TAMPERED_FIX if package else REBUILD_FIX
    manifest = read_json(path, "study manifest", fix=fix)
    missing = ([key for key in MANIFEST_KEYS if key not in manifest and key not in MANIFEST_OPTIONAL_KEYS]
               if isinstance(manifest, dict) else ["all"])
    if missing or not isinstance(manifest, dict):   # not a dict: missing is ["all"]
        raise InputError(str(path), missing[0], "missing manifest key", fix)
    return manifest
