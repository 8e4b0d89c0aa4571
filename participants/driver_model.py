"""Driver model files: trust dynamics, takeover model, AV failure model; validation.

Schema (JSON, as the packaged default `data/driver_model.json`):
- `trust_levels`: [1, ..., 7]
- `incident_types`: the incident kinds the model covers
- `takeover_probability`: {incident: [P(takeover | θ) for θ in trust_levels]}
- `trust_transition`: {incident: {"takeover": M, "standstill": M}} with M a row-stochastic
  |Θ|x|Θ| matrix (row = trust before, column = trust after). To let trust depend on the
  AV's performance, M may instead be {"succ": M_succ, "fail": M_fail}.
- `failure_probability` (optional): {incident: [P(e = fail | θ) ...]}; absent means the AV
  always succeeds (the default model).
- `initial_belief` (optional, uniform when absent), `source` (provenance text).

Every key and its check: docs/formats/driver_model.md.

Index conventions used by every array here and in `policies/`:
h = 0 standstill, 1 takeover; e = 0 succ, 1 fail.

Also owns the trust-report noise model (`report_matrix`, `draw_report`): a driver reports its true
trust with probability `accuracy`, else one level up or down (equal chance), clipped at the ends
(so at the lowest and highest level a wrong report can still equal the truth). The synthetic
driver draws reports with it and analysis/fitting/driver_model.py fits it.
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TypedDict

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.fields import (
    EMPTY,
    PROBABILITY,
    Anything,
    Field,
    Integer,
    ListOf,
    Table,
    Text,
    check_fields,
    field_table,
    holds_bool,
    keys,
)
from trustroute.core.packaged import PackagedKind
from trustroute.core.validation import check_keys, parse_json, read_text, require_object
from trustroute.core.wording import shown_value

DEFAULT_DRIVER_MODEL_PATH = Path(__file__).parent / "data" / "driver_model.json"
# the packaged driver models by name (participants/data/driver_model*.json)
DRIVER_MODELS = PackagedKind("driver model", DEFAULT_DRIVER_MODEL_PATH.parent, ".json", "driver_model")
HUMAN_ACTIONS: tuple[str, ...] = ("standstill", "takeover")
Performance = Literal["succ", "fail"]
PERFORMANCES: tuple[Performance, ...] = ("succ", "fail")
ROW_TOLERANCE = 1e-9
DEFAULT_REPORT_ACCURACY = 0.8   # P(a trust report is the true level)


def report_matrix(accuracy: float | np.ndarray, k: int) -> np.ndarray:
    """R[θ, r] = P(report index r | trust index θ) over k levels: the noise model of reports. An
    array of accuracies gives one matrix per accuracy ([..., k, k])."""
    accuracy = np.asarray(accuracy, dtype=float)
    matrix = np.zeros((*accuracy.shape, k, k))
    half = (1 - accuracy) / 2
    for theta in range(k):
        matrix[..., theta, theta] += accuracy
        matrix[..., theta, max(theta - 1, 0)] += half
        matrix[..., theta, min(theta + 1, k - 1)] += half
    return matrix


def draw_report(theta: int, accuracy: float, k: int, rng: np.random.Generator) -> int:
    """One report index drawn from row θ of `report_matrix(accuracy, k)` (through `rng`)."""
    if rng.random() < accuracy:
        return theta
    step = -1 if rng.random() < 0.5 else 1
    return min(max(theta + step, 0), k - 1)

MAX_TRUST_LEVELS = 100  # the model is dense in |Θ|^2 per incident; real scales have 5-11 levels
MAX_INCIDENT_TYPES = 64
MAX_NAME = 64


@dataclass(frozen=True, eq=False)
class DriverTables:
    """The tables of driver models (kinds) on one incident list; arrays are read-only.

    takeover[k, i, θ]              = P(h = takeover | θ, incident i) of kind k
    failure[k, i, θ]               = P(e = fail | θ, incident i)
    transition_cdf[k, i, h, e, θ]  = the cumulative row of T[i][h][e](θ, ·)
    initial_cdf[k]                 = the cumulative initial distribution of θ
    """

    incident_types: tuple[str, ...]
    takeover: np.ndarray
    failure: np.ndarray
    transition_cdf: np.ndarray
    initial_cdf: np.ndarray

    def __post_init__(self) -> None:
        for name in ("takeover", "failure", "transition_cdf", "initial_cdf"):
            getattr(self, name).setflags(write=False)


def driver_tables(models: Sequence[DriverModel],
                  incident_types: Sequence[str] | None = None) -> DriverTables:
    """The tables of `models` (kind k = models[k]) indexed by `incident_types` (default: the first
    model's); every model must cover those incidents and have as many trust levels."""
    models = list(models)
    if not models:
        raise ValueError("driver_tables needs at least one driver model")
    incidents = tuple(incident_types) if incident_types is not None else models[0].incident_types
    if any(m.n_trust != models[0].n_trust for m in models):
        raise ValueError("the driver models have different numbers of trust levels")
    for m in models:
        missing = [i for i in incidents if i not in m.incident_types]
        if missing:
            raise ValueError(f"driver model {m.source_path} does not cover incident {missing[0]!r}")
    rows = [[m.incident_index(i) for i in incidents] for m in models]
    return DriverTables(
        incident_types=incidents,
        takeover=np.stack([m.takeover_probability[r] for m, r in zip(models, rows, strict=True)]),
        failure=np.stack([m.failure_probability[r] for m, r in zip(models, rows, strict=True)]),
        transition_cdf=np.cumsum(
            np.stack([m.trust_transition[r] for m, r in zip(models, rows, strict=True)]), axis=-1),
        initial_cdf=np.cumsum(np.stack([m.initial_belief for m in models]), axis=-1),
    )


@dataclass(frozen=True, eq=False)
class DriverModel:
    """A validated driver model; arrays are read-only.

    takeover_probability[i, θ]      = P(h = takeover | θ, incident i)
    failure_probability[i, θ]       = P(e = fail | θ, incident i)
    trust_transition[i, h, e, θ, θ'] = P(θ' | θ, incident i, h, e)
    """

    trust_levels: tuple[int, ...]
    incident_types: tuple[str, ...]
    takeover_probability: np.ndarray
    failure_probability: np.ndarray
    trust_transition: np.ndarray
    initial_belief: np.ndarray
    trust_free_takeover_probability: dict[str, float]
    source_path: str = ""
    provenance: str = ""

    def __post_init__(self) -> None:
        for name in ("takeover_probability", "failure_probability", "trust_transition",
                     "initial_belief"):
            array = np.array(getattr(self, name), dtype=float)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def n_trust(self) -> int:
        return len(self.trust_levels)

    def incident_index(self, incident: str) -> int:
        return self.incident_types.index(incident)

    @property
    def depends_on_performance(self) -> bool:
        return bool(self.failure_probability.any())

    @functools.cached_property
    def tables(self) -> DriverTables:
        """`driver_tables([self])`: the model's own tables on its incident list (kind 0), built
        once and held here (a study makes a synthetic driver per episode from a few models)."""
        return driver_tables([self])

    @functools.cached_property
    def content_hash(self) -> str:
        digest = hashlib.sha256()
        digest.update(json.dumps([list(self.trust_levels), list(self.incident_types)]).encode())
        for array in (self.takeover_probability, self.failure_probability,
                      self.trust_transition, self.initial_belief):
            digest.update(np.ascontiguousarray(array, dtype="<f8").tobytes())
        return digest.hexdigest()

    def to_dict(self) -> dict:
        """The file form of this model (always the explicit succ/fail form when it needs it)."""
        transitions: dict[str, dict] = {}
        for i, incident in enumerate(self.incident_types):
            transitions[incident] = {}
            for h, action in enumerate(HUMAN_ACTIONS):
                if self.depends_on_performance:
                    transitions[incident][action] = {
                        perf: self.trust_transition[i, h, e].tolist()
                        for e, perf in enumerate(PERFORMANCES)
                    }
                else:
                    transitions[incident][action] = self.trust_transition[i, h, 0].tolist()
        out = {
            "trust_levels": list(self.trust_levels),
            "incident_types": list(self.incident_types),
            "takeover_probability": {
                inc: self.takeover_probability[i].tolist()
                for i, inc in enumerate(self.incident_types)
            },
            "trust_transition": transitions,
            "trust_free_takeover_probability": dict(self.trust_free_takeover_probability),
            "initial_belief": self.initial_belief.tolist(),
            "source": self.provenance,
        }
        if not self.trust_free_takeover_probability:
            del out["trust_free_takeover_probability"]   # an empty table is a table without its entries
        if self.depends_on_performance:
            out["failure_probability"] = {
                inc: self.failure_probability[i].tolist()
                for i, inc in enumerate(self.incident_types)
            }
        return out


# -- loading and validation -------------------------------------------------
# Every key of a driver model file (docs/formats/driver_model.md); the rules below check what a table
# cannot (entries per incident type, array shapes, rows summing to 1).

UNIFORM_BELIEF = object()  # initial_belief absent: the uniform distribution over the trust levels
_BY_INCIDENT = "expected an object keyed by incident type"
_BY_INCIDENT_FIX = "write {\"obstacle\": ..., ...}"
IncidentTable = Literal["takeover_probability", "trust_transition", "failure_probability",
                        "trust_free_takeover_probability"]


class DriverModelValues(TypedDict):
    """A driver model file's checked values (FIELDS)."""

    trust_levels: list[int]
    incident_types: list[str]
    takeover_probability: dict[str, object]
    trust_transition: dict[str, object]
    failure_probability: Mapping[str, object]
    initial_belief: object
    trust_free_takeover_probability: Mapping[str, float]
    source: object


class PerformanceMatrices(TypedDict):
    """trust_transition.<incident>.<action> split by the AV's performance (PERFORMANCE_FIELDS)."""

    succ: object
    fail: object


FIELDS = field_table(
    DriverModelValues,
    Field(key="trust_levels", required=True,
          kind=ListOf(item=Integer(), min_items=2, max_items=MAX_TRUST_LEVELS, increasing=True),
          problem=lambda seen: (f"{shown_value(seen.value, 60)} is not an increasing list of 2 to "
                                f"{MAX_TRUST_LEVELS} integers"),
          fix="write e.g. [1, 2, 3, 4, 5, 6, 7]", missing_fix="add 'trust_levels' as in the default model"),
    Field(key="incident_types", required=True,
          kind=ListOf(item=Text(max_length=MAX_NAME), min_items=1, max_items=MAX_INCIDENT_TYPES,
                      distinct=True),
          problem="expected a list of distinct incident names",
          fix="write e.g. [\"obstacle\", \"pedestrian\", \"truck\", \"none\"]",
          missing_fix="add 'incident_types' as in the default model"),
    Field(key="takeover_probability", kind=Table(), required=True, problem=_BY_INCIDENT, fix=_BY_INCIDENT_FIX,
          missing_fix="add 'takeover_probability' as in the default model"),
    Field(key="trust_transition", kind=Table(), required=True, problem=_BY_INCIDENT, fix=_BY_INCIDENT_FIX,
          missing_fix="add 'trust_transition' as in the default model"),
    Field(key="failure_probability", kind=Table(), default=EMPTY, problem=_BY_INCIDENT, fix=_BY_INCIDENT_FIX),
    # one probability per trust level, summing to 1 (_initial_belief)
    Field(key="initial_belief", kind=Anything(), default=UNIFORM_BELIEF),
    Field(key="trust_free_takeover_probability", kind=Table(values=PROBABILITY), default=EMPTY,
          problem="expected an object", fix="write {incident: probability}"),
    Field(key="source", kind=Anything(), default=""),  # provenance, kept as text
)
DRIVER_MODEL_KEYS: tuple[str, ...] = keys(FIELDS)
INCIDENT_TABLES: tuple[IncidentTable, ...] = ("takeover_probability", "trust_transition",
                                              "failure_probability", "trust_free_takeover_probability")
# trust_transition.<incident>.<action> may be split by the AV's performance
PERFORMANCE_FIELDS = field_table(PerformanceMatrices, *(
    Field(key=perf, kind=Anything(), required=True, missing=f"missing '{perf}' matrix",
          fix="give both 'succ' and 'fail' matrices") for perf in PERFORMANCES))


def _numbers(value: object, path: str, place: str, expected: str, fix: str) -> np.ndarray:
    """A float array of the (nested) list `value`; `true`/`false` are not numbers."""
    if holds_bool(value):
        raise InputError(path, place, f"{expected}, not true or false",
                         "write the number 1 or 0 (true and false are not numbers)")
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(path, place, expected, fix) from None


def _probabilities(value: object, length: int, path: str, place: str) -> np.ndarray:
    array = _numbers(value, path, place, f"expected {length} numbers",
                     f"write a list of {length} probabilities")
    if array.shape != (length,):
        raise InputError(path, place, f"expected {length} numbers, got shape {array.shape}",
                         f"give one probability per trust level ({length})")
    if not np.all(np.isfinite(array)) or array.min() < 0 or array.max() > 1:
        raise InputError(path, place, "probabilities must lie in [0, 1]",
                         "fix the out-of-range entries")
    return array


def _stochastic_matrix(value: object, n: int, path: str, place: str) -> np.ndarray:
    matrix = _numbers(value, path, place, "expected a matrix of numbers",
                      f"write a {n}x{n} row-stochastic matrix")
    if matrix.shape != (n, n):
        raise InputError(path, place, f"expected a {n}x{n} matrix, got shape {matrix.shape}",
                         "give one row per trust level before and one column per level after")
    if not np.all(np.isfinite(matrix)) or matrix.min() < 0 or matrix.max() > 1:
        raise InputError(path, place, "entries must lie in [0, 1]",
                         "fix the out-of-range entries")
    sums = matrix.sum(axis=1)
    bad = np.flatnonzero(np.abs(sums - 1) > ROW_TOLERANCE)
    if bad.size:
        row = int(bad[0])
        raise InputError(path, f"{place}[{row}]", f"row sums to {sums[row]:.12g}, not 1 "
                         f"(tolerance {ROW_TOLERANCE:g})", "renormalise the row")
    return matrix


def _check_incident_keys(values: DriverModelValues, incidents: list[str], path: str) -> None:
    """The tables keyed by incident type name only incident types of the model."""
    for key in INCIDENT_TABLES:
        extra = sorted(set(values[key]) - set(incidents))
        if extra:
            raise InputError(path, f"{key}.{extra[0]}", f"'{extra[0]}' is not in incident_types",
                             "add it to incident_types or remove the entry")


def _check_trust_free_entries(values: DriverModelValues, incidents: list[str], given: bool,
                              path: str) -> None:
    """The trust-free table, when given, has an entry for every incident type, as every table keyed
    by incident type but the failure model must (a partial table is a mistake, not a choice)."""
    table = values["trust_free_takeover_probability"]
    missing = [incident for incident in incidents if incident not in table]
    if given and missing:
        raise InputError(path, f"trust_free_takeover_probability.{missing[0]}",
                         f"missing trust-free takeover probability for '{missing[0]}'",
                         "add one probability per incident type, or leave out the whole table")


def _action_matrices(entry: object, n: int, path: str, place: str) -> np.ndarray:
    """[e, θ, θ'] for one human action: a plain matrix (both performances) or {"succ", "fail"}."""
    if not isinstance(entry, dict):
        matrix = _stochastic_matrix(entry, n, path, place)
        return np.stack([matrix, matrix])
    matrices = check_fields(entry, PERFORMANCE_FIELDS, path, "driver model", place)
    return np.stack([_stochastic_matrix(matrices[perf], n, path, f"{place}.{perf}") for perf in PERFORMANCES])


def _transitions(rows: object, incident: str, n: int, path: str) -> np.ndarray:
    """[h, e, θ, θ'] of one incident type: both human actions' matrices present and stochastic."""
    place = f"trust_transition.{incident}"
    if not isinstance(rows, dict):
        raise InputError(path, place, f"missing trust transition for '{incident}'",
                         "add {\"takeover\": M, \"standstill\": M}")
    check_keys(rows, HUMAN_ACTIONS, path, place, "driver model")
    for action in HUMAN_ACTIONS:
        if action not in rows:
            raise InputError(path, f"{place}.{action}", f"missing '{action}' matrix",
                             f"add a {n}x{n} row-stochastic matrix")
    return np.stack([_action_matrices(rows[action], n, path, f"{place}.{action}")
                     for action in HUMAN_ACTIONS])


def _incident_arrays(values: DriverModelValues, incidents: list[str], n: int,
                     path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(takeover [i, θ], failure [i, θ], transition [i, h, e, θ, θ']) over the incident types."""
    takeover = np.zeros((len(incidents), n))
    failure = np.zeros((len(incidents), n))
    transition = np.zeros((len(incidents), 2, 2, n, n))
    takeover_table, failure_table = values["takeover_probability"], values["failure_probability"]
    for i, incident in enumerate(incidents):
        if incident not in takeover_table:
            raise InputError(path, f"takeover_probability.{incident}",
                             f"missing takeover probabilities for '{incident}'",
                             f"add {n} probabilities, one per trust level")
        takeover[i] = _probabilities(takeover_table[incident], n, path, f"takeover_probability.{incident}")
        if incident in failure_table:
            failure[i] = _probabilities(failure_table[incident], n, path, f"failure_probability.{incident}")
        transition[i] = _transitions(values["trust_transition"].get(incident), incident, n, path)
    return takeover, failure, transition


def _initial_belief(value: object, n: int, path: str) -> np.ndarray:
    if value is UNIFORM_BELIEF:
        return np.full(n, 1.0 / n)
    initial = _probabilities(value, n, path, "initial_belief")
    if abs(initial.sum() - 1) > ROW_TOLERANCE:
        raise InputError(path, "initial_belief", f"sums to {initial.sum():.12g}, not 1",
                         "renormalise the initial belief")
    return initial


# The two files a researcher confuses, each told by a key only it has, and how a command takes it.
FILE_KINDS = {"driver model": ("trust_levels", "--driver", "docs/formats/driver_model.md"),
              "driver population": ("types", "--population", "docs/formats/driver_population.md")}


def refuse_the_other_kind(data: dict, path: str, expected: str) -> None:
    """A driver model given where a driver population goes, or the reverse: one line saying which it
    is, where the unknown-key error would name the first key of the other format."""
    for kind, (key, flag, _doc) in FILE_KINDS.items():
        if kind != expected and key in data and FILE_KINDS[expected][0] not in data:
            raise InputError(path, "top level", f"this is a {kind} file, not a {expected}",
                             f"pass it where a {kind} goes ({flag}), or a {expected} file here "
                             f"({FILE_KINDS[expected][2]})")


def driver_model_from_dict(data: object, path: str = "<driver model>") -> DriverModel:
    """Validate a parsed driver-model document, or raise InputError."""
    data = require_object(data, path, "start from the default model (participants/data/driver_model.json)")
    refuse_the_other_kind(data, path, "driver model")
    values = check_fields(data, FIELDS, path, "driver model")
    levels, incidents = values["trust_levels"], values["incident_types"]
    _check_incident_keys(values, incidents, path)
    _check_trust_free_entries(values, incidents, "trust_free_takeover_probability" in data, path)
    takeover, failure, transition = _incident_arrays(values, incidents, len(levels), path)
    free = values["trust_free_takeover_probability"]
    return DriverModel(
        trust_levels=tuple(levels),
        incident_types=tuple(incidents),
        takeover_probability=takeover,
        failure_probability=failure,
        trust_transition=transition,
        initial_belief=_initial_belief(values["initial_belief"], len(levels), path),
        trust_free_takeover_probability={str(k): float(v) for k, v in free.items()},
        source_path=path,
        provenance=str(values["source"]),
    )


def driver_model_file(path: str | Path | None) -> Path:
    """The file a driver model argument or a study's recorded model names: `DRIVER_MODELS.resolve`,
    the packaged default model for None."""
    return DRIVER_MODELS.resolve(path) if path is not None else DEFAULT_DRIVER_MODEL_PATH


def load_driver_model(path: str | Path | None = None) -> DriverModel:
    """Load and validate a driver model file or a packaged model by name (`DRIVER_MODELS`:
    "driver_model", "driver_model_performance"; the packaged default when `path` is None), read
    through the guarded reader (trustroute.core.validation)."""
    file_path = driver_model_file(path)
    shown = "default driver model" if path is None else str(path if file_path == Path(path) else file_path)
    text = read_text(file_path, shown, "the driver model", DRIVER_MODELS.fix("--driver"))
    return driver_model_from_text(text, shown)


def driver_model_from_text(text: str, shown: str) -> DriverModel:
    """Parse and validate the text of a driver model file; `shown` names it in errors."""
    return driver_model_from_dict(parse_json(text, shown, "driver model"), shown)


def check_covers_town(model: DriverModel, town_incidents: set[str], town_source: str) -> None:
    """Every incident type the town uses must be in the driver model."""
    missing = sorted(town_incidents - set(model.incident_types))
    if missing:
        raise InputError(model.source_path, "incident_types",
                         f"the town {town_source} uses incident '{missing[0]}' which the model "
                         "does not cover", f"add '{missing[0]}' with its takeover probabilities "
                         "and trust transitions")
