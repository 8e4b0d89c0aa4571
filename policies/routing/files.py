"""Policy files: a synthesized policy on disk, bound to the town, driver model and spec it was made for.

`save_policy(result, path, town, driver, spec)` writes `path` (JSON: format, content hashes of
town, driver model and spec, horizon, belief rule, bounds, the acting rule in words, and the name
and SHA-256 of the array file) and `path` with suffix `.npz` (the decision table: its table kind's
rows, policies/routing/decision_tables.py: exact rows and the box rows of a cluster policy, or
the joint rows of a spec with trust-state atoms).
`load_policy(path, town, driver, spec)` checks the format and all three hashes and raises
InputError naming the file and the fix on a mismatch.
Every key: docs/formats/policy_file.md.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_bytes, atomic_write_text
from trustroute.core.package import check_outside_package
from trustroute.core.validation import MAX_ARRAY_BYTES, check_keys, decode_utf8, parse_json, read_input_bytes
from trustroute.core.wording import shown_value
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.driver_types import TypeLiftedModel, lift_population, lift_spec
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.decision_tables import (
    BOX_ROWS,
    EXACT_ROWS,
    JOINT_ROWS,
    JOINT_TABLE,
    PLAIN_TABLE,
    RESYNTH,
    TABLE_KINDS,
    PolicyOrigin,
    ReadContext,
    TableKind,
    check_junction_count,
    document_table_kind,
    table_kind,
)
from trustroute.policies.routing.protocol import RoutingPolicy

FORMAT = "trustroute-policy"
ZIP_MAGIC = b"PK\x03\x04"  # the first bytes of every .npz (a zip archive)
# The version written; the versions each table kind is read from: policies/routing/decision_tables.py.
VERSION = 4

ARRAY_NAMES = EXACT_ROWS.names
BOX_ARRAY_NAMES = BOX_ROWS.names
# A policy synthesized for a driver population of several types also records these
# (docs/formats/policy_file.md, "Population policies"); one type writes the single-model file.
POPULATION_KEYS = ("population_hash", "population_types", "population_weights", "belief_prior",
                   "objective", "objective_lower", "objective_upper", "type_values")
# Every policy file has PLAIN_KEYS; a population policy has POPULATION_KEYS besides.
PLAIN_KEYS = ("format", "version", "name", "spec", "town_hash", "driver_hash", "spec_hash", "horizon",
              "belief_rule", "lower", "upper", "gap", "seconds", "rows", "box_rows", "acting_rule",
              "arrays", "arrays_sha256")
DOCUMENT_KEYS = PLAIN_KEYS + POPULATION_KEYS
# Policies of specs with trust-state atoms act on the joint belief (policies/routing/trust_state_table.py):
# their files have the keys JOINT_KEYS besides, and the arrays JOINT_ARRAY_NAMES.
JOINT_KIND = JOINT_TABLE.kind
JOINT_KEYS = JOINT_TABLE.keys
JOINT_ARRAY_NAMES = JOINT_ROWS.names


def array_path(path: str | Path) -> Path:
    return Path(path).with_suffix(".npz")


def save_policy(result, path: str | Path, town: Town, driver: DriverModel, spec: Spec,
                population: dict | None = None, name: str = "aware") -> Path:
    """Write the policy of a SynthesisResult to `path` (+ `.npz`); returns the JSON path.
    population: the POPULATION_KEYS entries of a policy made for several driver types (driver and
    spec are then the lifted ones, policies/belief/driver_types.py)."""
    path = Path(path)
    check_outside_package(path, "--out", "policy file")   # every door's: a package is read-only
    table = result.policy.table
    kind = table_kind(table)
    arrays = array_path(path)
    buffer = io.BytesIO()
    # Numeric arrays only: readers refuse pickles.
    np.savez_compressed(buffer, allow_pickle=False, **kind.arrays(table))
    array_bytes = buffer.getvalue()
    # The arrays first, the JSON (which names their hash) last: the JSON is the commit mark.
    atomic_write_bytes(arrays, array_bytes, "policy array file", "pass a writable --out path")
    document = {
        "format": FORMAT,
        "version": VERSION,
        "name": name,
        "spec": spec.name,
        "town_hash": town.content_hash,
        "driver_hash": driver.content_hash,
        "spec_hash": spec.content_hash,
        "horizon": result.horizon,
        "belief_rule": result.belief_rule,
        "lower": result.lower,
        "upper": result.upper,
        "gap": result.gap,
        "seconds": result.seconds,
        "rows": table.rows,
        "box_rows": 0 if kind is not PLAIN_TABLE or table.boxes is None else table.boxes.rows,
        "acting_rule": kind.acting_rule,
        "arrays": arrays.name,
        "arrays_sha256": hashlib.sha256(array_bytes).hexdigest(),
    }
    if population is not None:
        document.update({key: population[key] for key in POPULATION_KEYS})
    document.update(kind.document(result.policy))
    atomic_write_text(path, json.dumps(document, indent=1) + "\n", "policy file",
                      "pass a writable --out path")
    return path


def read_policy_document(path: str | Path) -> dict:
    """The JSON part of a policy file, checked for format (InputError otherwise)."""
    path = Path(path)
    where = str(path)
    data = read_input_bytes(path, "policy file", fix="pass 'free', 'aware' or a file written by trustroute "
                            "synth --out")
    if data.startswith(ZIP_MAGIC):
        raise _arrays_instead_of_policy(path)
    document = parse_json(decode_utf8(data, where, "policy file"), where, "policy file")
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise InputError(where, "format", f"not a trustroute policy file (format {FORMAT!r} expected)",
                         "pass a file written by trustroute synth --out")
    kind = document_table_kind(document)
    version = document.get("version")
    # A file naming a kind is read from the versions of any kind; one without, the plain versions.
    readable = ({v for k in TABLE_KINDS for v in k.versions} if "kind" in document
                else set(PLAIN_TABLE.versions))
    if version not in readable or isinstance(version, bool):
        older = ("; version 2 policies drive the state-only completion where they have no row, which "
                 "their bounds were certified for, not this trustroute's acting rule"
                 if version == 2 else "")
        raise InputError(where, "version", f"policy file version {shown_value(version, 30)}, this "
                         f"trustroute reads version {VERSION}{older}", "re-run trustroute synth")
    if kind is None:
        named = ", ".join(repr(k.kind) for k in TABLE_KINDS if k.kind is not None)
        raise InputError(where, "kind", f"unknown policy kind {shown_value(document['kind'], 30)} "
                         f"(only {named})", RESYNTH)
    check_keys(document, DOCUMENT_KEYS + kind.keys, where, "", "policy file")
    kind.check(document, where)
    check_junction_count(document.get("horizon"), "horizon", where)
    for key in ("lower", "upper"):
        value = document.get(key)
        if value is not None and not (isinstance(value, int | float) and not isinstance(value, bool)
                                      and math.isfinite(value) and 0 <= value <= 1):
            raise InputError(where, key, f"{key} bound {shown_value(value, 30)} is not a probability",
                             RESYNTH)
    if not isinstance(document.get("arrays"), str) or Path(document["arrays"]).name != document["arrays"]:
        raise InputError(where, "arrays", "must name the .npz file beside the policy file", RESYNTH)
    return document


def _arrays_instead_of_policy(path: Path) -> InputError:
    """The error for a policy's .npz (a zip archive) given where its JSON policy file belongs."""
    beside = path.with_suffix(".json")
    fix = (f"pass the policy file {beside} (the .json beside it names and checks this table)"
           if beside.is_file() and beside != path else
           "pass the policy's .json file, written beside its .npz by trustroute synth --out")
    return InputError(str(path), "", "this is a policy's decision table (its .npz array file), not "
                      "the policy file", fix)


def checked_table_kind(document: dict) -> TableKind[Any, Any]:
    """The table kind of a document that read_policy_document accepted (it names a known kind)."""
    kind = document_table_kind(document)
    if kind is None:
        raise AttributeError(f"policy document of unknown kind {shown_value(document.get('kind'), 30)}; "
                             "read it with read_policy_document")
    return kind


def read_policy_table(arrays: Path, document: dict, town: Town, driver: DriverModel, spec: Spec):
    """The decision table of a policy file, verified: the hash its JSON records, a readable .npz
    without pickles, the arrays of its table kind with consistent shapes and integer types, and
    every entry in range for this town, driver model and spec (InputError otherwise)."""
    where = str(arrays)
    if not arrays.exists():
        raise InputError(where, "arrays", "the policy's array file is missing",
                         "keep the .npz next to the policy file, or re-run trustroute synth")
    data = read_input_bytes(arrays, "policy array file", MAX_ARRAY_BYTES,
                            fix="keep the .npz next to the policy file, or re-run trustroute synth")
    if hashlib.sha256(data).hexdigest() != document.get("arrays_sha256"):
        raise InputError(where, "", "array file does not match its policy file (hash differs)", RESYNTH)
    kind = checked_table_kind(document)
    version = document.get("version", VERSION)
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            names = kind.block_names(version)
            missing = [name for name in names if name not in archive.files]
            if missing:
                raise InputError(where, missing[0], f"array '{missing[0]}' is missing", RESYNTH)
            arrays_read = {name: archive[name] for name in names}
    except InputError:
        raise
    except (OSError, ValueError, EOFError, KeyError, NotImplementedError, zipfile.BadZipFile,
            zipfile.LargeZipFile, zlib.error) as exc:
        raise InputError(where, "", f"not a readable .npz array file ({type(exc).__name__})",
                         RESYNTH) from None
    context = ReadContext(where=where, document=document, town=town, driver=driver, spec=spec,
                         n_q=compile_spec(spec, town).dfa.n_states)
    return kind.read(arrays_read, version, context)


def load_policy(path: str | Path, town: Town, driver: DriverModel, spec: Spec) -> RoutingPolicy:
    """Load a policy file made for exactly this town, driver model and spec."""
    path = Path(path)
    where = str(path)
    document = read_policy_document(path)
    made_for_population = document.get("population_hash")
    given_population = driver.population_hash if isinstance(driver, TypeLiftedModel) else ""
    if made_for_population is not None and given_population != made_for_population:
        given, synth = (("not for a single driver model", "without --population for the driver model")
                        if not given_population else ("not for the one given", "--population for this one"))
        raise InputError(where, "population_hash", "policy was synthesized for a driver population "
                         f"(hash {str(made_for_population)[:12]}...), {given}",
                         "pass the driver population it was made for (--population), or re-run "
                         f"trustroute synth {synth}")
    if made_for_population is None and given_population:
        raise InputError(where, "population_hash", "policy was synthesized for a single driver model, "
                         "not for a driver population", "pass the driver model it was made for "
                         "(--driver), or re-run trustroute synth --population")
    made_for = {"town": "", "driver model": "", "spec": f" {document.get('spec')!r}"}
    for key, what, value, option, name in (
            ("town_hash", "town", town.content_hash, "--town", ""),
            ("driver_hash", "driver model", driver.content_hash, "--driver", ""),
            ("spec_hash", "spec", spec.content_hash, "SPEC", f" {spec.name!r}")):
        if document.get(key) != value:
            raise InputError(where, key, f"policy was synthesized for another {what}{made_for[what]} "
                             f"(hash {str(document.get(key))[:12]}...; this {what}{name} has "
                             f"{value[:12]}...)",
                             f"re-run trustroute synth for this {what}, or pass the {what} it was "
                             f"made for ({option})")
    table = read_policy_table(path.parent / document["arrays"], document, town, driver, spec)
    origin = PolicyOrigin(document=document, town=town, driver=driver, spec=spec,
                          reweight=prior_reweight(document, driver.n_trust, where))
    return checked_table_kind(document).policy(table, origin)


def prior_reweight(document: dict, n_hidden: int, where: str = "policy file") -> np.ndarray | None:
    """The belief reweighting r = λ_k / w_k (per hidden index) of a population policy whose type
    prior λ differs from the population's weights w; None otherwise (policies/routing/aware_table.py)."""
    prior, weights = document.get("belief_prior"), document.get("population_weights")
    if prior is None or weights is None:
        return None
    try:
        prior_array = np.asarray(prior, dtype=float)
        weight_array = np.asarray(weights, dtype=float)
    except (TypeError, ValueError):
        raise InputError(where, "belief_prior", "expected lists of numbers", RESYNTH) from None
    if (prior_array.shape != weight_array.shape or prior_array.ndim != 1 or not prior_array.size
            or n_hidden % prior_array.size or not np.all(np.isfinite(prior_array))
            or (prior_array < 0).any() or not (weight_array > 0).all()):
        raise InputError(where, "belief_prior", "expected one nonnegative prior weight per type", RESYNTH)
    if np.array_equal(prior_array, weight_array):
        return None
    return np.repeat(prior_array / weight_array, n_hidden // prior_array.size)


def load_population_policy(path: str | Path, town: Town, population, spec: Spec,
                           population_source: str = ""):
    """A policy file for routing with driver population `population` (a DriverPopulation):
    (policy, the lifted driver model its AV filters with, the lifted spec). The lifted model uses
    the type prior the file records. A file made for another population or spec, or for a single
    driver model while the population has several types: InputError (one line, exit 2)."""
    document = read_policy_document(path)
    lifted_spec = lift_spec(spec, population, population_source)
    if document.get("population_hash") not in (None, population.content_hash):
        raise InputError(str(path), "population_hash", "policy was synthesized for another driver "
                         f"population (hash {str(document['population_hash'])[:12]}...; the population "
                         f"{population_source or population.source_path} has "
                         f"{population.content_hash[:12]}...)",
                         "pass the population it was made for, or re-run trustroute synth --population")
    model = lift_population(population)
    return load_policy(path, town, model, lifted_spec), model, lifted_spec
