"""Driver-population files: a finite mixture of driver types, each a full driver model, with
prior weights; validation, loading, writing.

Schema (JSON; every key and its check: docs/formats/driver_population.md):
- `format`: "trustroute-driver-population", `version`: 1
- `source` (optional): provenance text
- `types`: a non-empty list of `{"name": ..., "weight": ..., "model": {driver model}}` or
  `{"name": ..., "weight": ..., "model_file": "path relative to this file"}`; the driver model is
  the document `participants/driver_model.py` reads (docs/formats/driver_model.md).

Every type shares the trust levels and incident types of the first; weights are > 0 and sum to 1
within `WEIGHT_TOLERANCE`, and are divided by their sum whenever a population is made (loaded from a
file or built in code: `DriverPopulation.__post_init__`), so every consumer weighs with a
distribution; names are unique. A population of one type of weight 1 is a single
driver model (`single_type_population`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TypedDict

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.fields import (
    Anything,
    Field,
    ListOf,
    Number,
    OneOf,
    Seen,
    Text,
    check_fields,
    check_value,
    field_table,
    keys,
)
from trustroute.core.output_files import atomic_write_text
from trustroute.core.packaged import PackagedKind
from trustroute.core.validation import decode_utf8, parse_json, read_input_bytes, read_text, require_object
from trustroute.core.wording import shown_value
from trustroute.participants.driver_model import (
    DRIVER_MODELS,
    DriverModel,
    driver_model_from_dict,
    driver_model_from_text,
    refuse_the_other_kind,
)

POPULATION_FORMAT = "trustroute-driver-population"
POPULATION_VERSION = 1
WEIGHT_TOLERANCE = 1e-9
MAX_TYPES = 64
TYPE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_-]{0,63}")
EXAMPLE_POPULATION_PATH = Path(__file__).parent / "data" / "driver_population_three_types.json"
# the packaged populations by name (participants/data/driver_population*.json)
POPULATIONS = PackagedKind("driver population", EXAMPLE_POPULATION_PATH.parent, ".json", "driver_population")


@dataclass(frozen=True)
class DriverType:
    """One type of the mixture: its name, prior weight and driver model."""

    name: str
    weight: float
    model: DriverModel


@dataclass(frozen=True)
class DriverPopulation:
    """A validated finite mixture of driver types (weights > 0, summing to 1)."""

    types: tuple[DriverType, ...]
    source_path: str = ""
    provenance: str = ""

    def __post_init__(self) -> None:
        # One rule for a population loaded from a file and one built in code: weights within the
        # tolerance of 1 become a distribution (the Bayes objective and every per-type bound weigh
        # with them), others are refused; so is a weight that is not a finite number > 0 (a NaN
        # would pass the sum's test, a negative one would weigh a type against the others), checked
        # by the file's own field (a bool, a string or None is refused as there, a numpy number or a
        # Fraction taken as its float).
        where = self.source_path or "<driver population>"
        weights = [check_value(t.weight, WEIGHT_KIND, where, f"types[{index}].weight", WEIGHT.problem,
                               WEIGHT.fix, Seen(WEIGHT.key, t.weight))
                   for index, t in enumerate(self.types)]
        total = math.fsum(weights)
        if abs(total - 1.0) > WEIGHT_TOLERANCE:
            raise InputError(where, "types",
                             f"the weights sum to {total:.12g}, not 1 (tolerance {WEIGHT_TOLERANCE:g})",
                             "renormalise the prior weights")
        normalised = zip(self.types, as_distribution(weights), strict=True)
        object.__setattr__(self, "types", tuple(replace(t, weight=w) for t, w in normalised))

    @property
    def n_types(self) -> int:
        return len(self.types)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.types)

    @property
    def weights(self) -> np.ndarray:
        array = np.array([t.weight for t in self.types], dtype=float)
        array.setflags(write=False)
        return array

    @property
    def models(self) -> tuple[DriverModel, ...]:
        return tuple(t.model for t in self.types)

    def type_index(self, name: str) -> int:
        return self.names.index(name)

    @functools.cached_property
    def content_hash(self) -> str:
        """SHA-256 of the names, the weights (as little-endian float64) and each model's hash."""
        digest = hashlib.sha256()
        digest.update(json.dumps([POPULATION_FORMAT, POPULATION_VERSION, list(self.names)]).encode())
        digest.update(np.ascontiguousarray(self.weights, dtype="<f8").tobytes())
        for t in self.types:
            digest.update(t.model.content_hash.encode())
        return digest.hexdigest()

    def to_dict(self) -> dict:
        """The file form, every model inline."""
        return {
            "format": POPULATION_FORMAT,
            "version": POPULATION_VERSION,
            "source": self.provenance,
            "types": [{"name": t.name, "weight": float(t.weight), "model": t.model.to_dict()}
                      for t in self.types],
        }


# -- loading and validation -------------------------------------------------
# Every key of a driver-population file and of one of its types (docs/formats/driver_population.md).

class PopulationValues(TypedDict):
    """A driver-population file's checked values (FIELDS)."""

    format: str
    version: int
    source: str
    types: list[object]


class TypeValues(TypedDict):
    """One type entry's checked values (TYPE_FIELDS)."""

    name: str
    weight: float
    model: object
    model_file: str | None


FIELDS = field_table(
    PopulationValues,
    Field(key="format", kind=OneOf(choices=(POPULATION_FORMAT,)), required=True,
          problem=lambda seen: f"{shown_value(seen.value, 60)} is not a driver-population file",
          fix=f"write \"format\": \"{POPULATION_FORMAT}\"",
          missing_fix="add 'format' as in participants/data/driver_population_three_types.json"),
    Field(key="version", kind=OneOf(choices=(POPULATION_VERSION,)), required=True,
          problem=lambda seen: f"version {shown_value(seen.value, 20)} is not supported",
          fix=f"write \"version\": {POPULATION_VERSION}",
          missing_fix="add 'version' as in participants/data/driver_population_three_types.json"),
    Field(key="source", kind=Text(nonempty=False), default="", problem="expected text",
          fix="write the provenance as a string"),
    Field(key="types", kind=ListOf(min_items=1, max_items=MAX_TYPES), required=True,
          problem=f"expected a list of 1 to {MAX_TYPES} driver types",
          fix="list the types as {\"name\", \"weight\", \"model\"} objects",
          missing_fix="add 'types' as in participants/data/driver_population_three_types.json"),
)
POPULATION_KEYS: tuple[str, ...] = keys(FIELDS)
_NAME_AND_WEIGHT = "give every type a name and a prior weight"
# a type's prior weight, in a file and in a population built in code (`DriverPopulation`)
WEIGHT_KIND = Number(minimum=0.0, open_below=True)
WEIGHT = Field(key="weight", kind=WEIGHT_KIND, required=True,
               problem=lambda seen: f"{shown_value(seen.value)} is not a positive number",
               fix="give a prior weight > 0 (the weights sum to 1)", missing_fix=_NAME_AND_WEIGHT)
TYPE_FIELDS = field_table(
    TypeValues,
    Field(key="name", kind=Text(pattern=TYPE_NAME), required=True,
          problem=lambda seen: f"{shown_value(seen.value, 60)} is not a type name",
          fix="use letters, digits, '_' or '-' (at most 64, starting with a letter or '_')",
          missing_fix=_NAME_AND_WEIGHT),
    WEIGHT,
    Field(key="model", kind=Anything()),  # a driver model document (participants/driver_model.py)
    Field(key="model_file", kind=Text(pattern=re.compile(r"[^\x00]+")), problem="expected a file path",
          fix="name the driver model file relative to this population file"),
)
TYPE_KEYS: tuple[str, ...] = keys(TYPE_FIELDS)


def _type_entry(entry: object, index: int, path: str, base: Path | None) -> tuple[str, float, DriverModel]:
    place = f"types[{index}]"
    if not isinstance(entry, dict):
        raise InputError(path, place, "expected an object with name, weight and model or model_file",
                         "write e.g. {\"name\": \"builder\", \"weight\": 0.4, \"model_file\": \"b.json\"}")
    values = check_fields(entry, TYPE_FIELDS, path, "driver population", place)
    file = values["model_file"]
    if (values["model"] is None) == (file is None):
        raise InputError(path, place, "give exactly one of 'model' and 'model_file'",
                         "inline the driver model or name its file relative to this one")
    if isinstance(values["model"], str):
        raise InputError(path, f"{place}.model", f"expected a driver model (an object), got "
                         f"{shown_value(values['model'])}", f"to name a driver model file or a packaged "
                         f"model, write \"model_file\": {json.dumps(values['model'][:80])}")
    if file is None:
        model = driver_model_from_dict(values["model"], f"{path} ({place}.model)")
    else:
        model = _model_file(file, base, path, f"{place}.model_file")
    return values["name"], float(values["weight"]), model


def _model_file(file: str, base: Path | None, path: str, place: str) -> DriverModel:
    """The driver model a type's `model_file` names. A file that cannot be read (missing, a
    directory, far too large) is an error of the population file at that key; what is wrong inside
    the model file is an error of the model file."""
    model_path = DRIVER_MODELS.resolve(file, base)
    try:
        data = read_input_bytes(model_path, f"driver model {file[:80]!r}")
    except InputError as exc:
        raise InputError(path, place, exc.problem, f"set {place} to an existing driver model file, "
                         "relative to the population file's folder, or a packaged driver model name "
                         f"({', '.join(DRIVER_MODELS.names())})") from None
    shown = str(model_path)
    return driver_model_from_text(decode_utf8(data, shown, "driver model"), shown)


def _check_alike(types: list[DriverType], index: int, path: str) -> None:
    """Type `index` (the last of `types`) has its own name and the first type's trust scale and
    incident types."""
    new, first = types[-1], types[0]
    if new.name in (t.name for t in types[:-1]):
        raise InputError(path, f"types[{index}].name", f"type name '{new.name}' appears twice",
                         "give every type its own name")
    if new.model.trust_levels != first.model.trust_levels:
        raise InputError(path, f"types[{index}]", f"type '{new.name}' has trust levels "
                         f"{list(new.model.trust_levels)}, not {list(first.model.trust_levels)} as type "
                         f"'{first.name}'", "every type must use the same trust scale")
    if new.model.incident_types != first.model.incident_types:
        raise InputError(path, f"types[{index}]", f"type '{new.name}' covers incidents "
                         f"{list(new.model.incident_types)}, not {list(first.model.incident_types)} as type "
                         f"'{first.name}'", "every type must list the same incident types in the "
                         "same order")


def driver_population_from_dict(data: object, path: str = "<driver population>") -> DriverPopulation:
    """Validate a parsed driver-population document, or raise InputError. A `model_file` is read
    relative to the folder of `path` (when `path` names a file)."""
    data = require_object(data, path, "start from participants/data/driver_population_three_types.json")
    refuse_the_other_kind(data, path, "driver population")
    values = check_fields(data, FIELDS, path, "driver population")
    candidate = Path(path)
    base = candidate.parent if candidate.is_file() else None
    types: list[DriverType] = []
    for index, entry in enumerate(values["types"]):
        name, weight, model = _type_entry(entry, index, path, base)
        types.append(DriverType(name=name, weight=weight, model=model))
        _check_alike(types, index, path)
    return DriverPopulation(types=tuple(types), source_path=path, provenance=values["source"])


def as_distribution(weights: list[float]) -> list[float]:
    """`weights` divided by their sum, with the rounding left over given to the largest, so that
    they sum to exactly 1.0 (math.fsum) and loading them again changes nothing: a population
    written back as loaded keeps its weights and content hash. Weights summing to exactly 1.0 come
    back as they are: divided by 1.0, with nothing left over."""
    total = math.fsum(weights)
    out = [w / total for w in weights]
    largest = max(range(len(out)), key=out.__getitem__)
    for _ in range(4):   # each pass leaves at most half an ulp of the largest; two suffice in practice
        left = 1.0 - math.fsum(out)
        if not left:
            break
        out[largest] += left
    return out


def load_driver_population(path: str | Path, given: str = "--population") -> DriverPopulation:
    """Load and validate a driver-population file or a packaged population by name (`POPULATIONS`:
    "driver_population_three_types", "driver_population_real") through the guarded reader.
    `given`: how the command line takes it, named in the hint when it cannot be read."""
    file_path = POPULATIONS.resolve(path)
    shown = str(path if file_path == Path(path) else file_path)
    text = read_text(file_path, shown, "the driver population", POPULATIONS.fix(given))
    return driver_population_from_dict(parse_json(text, shown, "driver population"), shown)


def write_driver_population(population: DriverPopulation, path: str | Path) -> Path:
    """Write `population` (every model inline) atomically; returns the path."""
    text = json.dumps(population.to_dict(), indent=2) + "\n"
    return atomic_write_text(path, text, "driver population")


def single_type_population(model: DriverModel, name: str = "nominal") -> DriverPopulation:
    """The population of one type of weight 1: a single driver model."""
    if not TYPE_NAME.fullmatch(name):
        raise ValueError(f"{name!r} is not a type name")
    return DriverPopulation(types=(DriverType(name=name, weight=1.0, model=model),),
                            source_path=model.source_path, provenance=model.provenance)
