"""Policy files: a synthesized policy on disk, bound to the town, driver model and spec it was made for.

`save_policy(result, path, town, driver, spec)` writes `path` (JSON: format, content hashes of
town, driver model and spec, horizon, belief rule, bounds, the acting rule in words, and the name
and SHA-256 of the array file) and `path` with suffix `.npz` (the decision table of
policies/routing/aware_table.py: t, x, q, projected, beliefs, action, and the box rows of a cluster
policy: box_t, box_x, box_q, box_lo, box_hi, box_value, box_action).
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

import numpy as np

from trustroute.core.errors import InputError
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.aware_table import BeliefTablePolicy, BoxRows, PolicyTable
from trustroute.policies.routing.free import state_only_task
from trustroute.policies.routing.trust_state_table import JointPolicyTable, JointTablePolicy

FORMAT = "trustroute-policy"
# Version 3: where a policy has no row it drives the free completion of (road, DFA state, task
# state), which after the state-only task returns to what the DFA still needs; version 2 files
# were synthesized for the state-only completion (then the first legal move) and are refused:
# their certified L is not the value of the version-3 rule. Joint-belief files (their rule does
# not use the completion) are read from version 2 on.
# Version 4 adds the box rows of cluster policies (box_* arrays, possibly empty); a version 3 file
# is read as a table without box rows, which the version 4 rule treats exactly as version 3 did.
VERSION = 4
PLAIN_VERSIONS = (3, 4)
JOINT_VERSIONS = (2, 3, 4)
ACTING_RULE = ("action of the stored row with the same (junctions driven, road, DFA state, state-only "
               "task state) whose belief is within 1e-12 of the AV's (the synthesis visited it); "
               "else, among the box rows of the same (junctions driven, road, DFA state) whose box "
               "holds the AV's belief, the action of the one of the largest value; "
               "else the move of the free completion: the trust-free shortest completion of the "
               "state-only task while it is not complete, then the shortest route back to what the "
               "DFA still needs, every label allowed (the first legal move where acceptance is "
               "unreachable)")


ARRAY_NAMES = ("t", "x", "q", "projected", "beliefs", "action")
BOX_ARRAY_NAMES = ("box_t", "box_x", "box_q", "box_lo", "box_hi", "box_value", "box_action")
# A policy synthesized for a driver population of several types also records these
# (docs/formats/policy_file.md, "Population policies"); one type writes today's file.
POPULATION_KEYS = ("population_hash", "population_types", "population_weights", "belief_prior",
                   "objective", "objective_lower", "objective_upper", "type_values")
# Every policy file has PLAIN_KEYS; a population policy has POPULATION_KEYS besides.
PLAIN_KEYS = ("format", "version", "name", "spec", "town_hash", "driver_hash", "spec_hash", "horizon",
              "belief_rule", "lower", "upper", "gap", "seconds", "rows", "box_rows", "acting_rule",
              "arrays", "arrays_sha256")
DOCUMENT_KEYS = PLAIN_KEYS + POPULATION_KEYS
# Policies of specs with trust-state atoms act on the joint belief (policies/routing/trust_state_table.py):
# their files have these keys besides, and the arrays JOINT_ARRAY_NAMES (no state-only task state:
# their rule does not read it; "joint" [rows, n_trust, n_q] instead).
JOINT_KIND = "joint-belief"
JOINT_KEYS = ("kind", "guide_horizon")
JOINT_ARRAY_NAMES = ("t", "x", "q", "beliefs", "action", "joint")
JOINT_ACTING_RULE = ("action of the stored row with the same (junctions driven, road) whose (joint "
                     "belief, belief) is within 1e-9 (Euclidean); else the successor with the largest "
                     "relaxed action value at the joint belief (policies/belief/trust_state_relaxation.py)")
RESYNTH = "re-run trustroute synth to write both files again"


def array_path(path: str | Path) -> Path:
    return Path(path).with_suffix(".npz")


def save_policy(result, path: str | Path, town: Town, driver: DriverModel, spec: Spec,
                population: dict | None = None, name: str = "aware") -> Path:
    """Write the policy of a SynthesisResult to `path` (+ `.npz`); returns the JSON path.
    population: the POPULATION_KEYS entries of a policy made for several driver types (driver and
    spec are then the lifted ones, policies/belief/driver_types.py)."""
    from trustroute.core.output_files import atomic_write_bytes, atomic_write_text

    path = Path(path)
    table: PolicyTable = result.policy.table
    joint = isinstance(result.policy, JointTablePolicy)
    arrays = array_path(path)
    buffer = io.BytesIO()
    if joint:
        np.savez_compressed(buffer, t=table.t, x=table.x, q=table.q, beliefs=table.beliefs,
                            action=table.action, joint=table.joint)
    else:
        if not table.exact:
            raise ValueError("only tables with the state-only task state (exact-belief rule) are written")
        boxes = table.boxes if table.boxes is not None else BoxRows.empty(table.beliefs.shape[1])
        np.savez_compressed(buffer, t=table.t, x=table.x, q=table.q, projected=table.projected,
                            beliefs=table.beliefs, action=table.action, box_t=boxes.t, box_x=boxes.x,
                            box_q=boxes.q, box_lo=boxes.lo, box_hi=boxes.hi, box_value=boxes.value,
                            box_action=boxes.action)
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
        "box_rows": 0 if joint or table.boxes is None else table.boxes.rows,
        "acting_rule": ACTING_RULE,
        "arrays": arrays.name,
        "arrays_sha256": hashlib.sha256(array_bytes).hexdigest(),
    }
    if population is not None:
        document.update({key: population[key] for key in POPULATION_KEYS})
    if joint:
        document["acting_rule"] = JOINT_ACTING_RULE
        document["kind"] = JOINT_KIND
        document["guide_horizon"] = result.policy.guide_horizon
    atomic_write_text(path, json.dumps(document, indent=1) + "\n", "policy file",
                      "pass a writable --out path")
    return path


def _check_junction_count(value: object, key: str, where: str) -> None:
    """A horizon of the header: a junction count from 0 to 10 000, or null (unbounded)."""
    count = isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 10_000
    if not (value is None or count):
        raise InputError(where, key, f"{key.replace('_', ' ')} {str(value)[:30]} is not a junction count or "
                         "null", RESYNTH)


def read_policy_document(path: str | Path) -> dict:
    """The JSON part of a policy file, checked for format (InputError otherwise)."""
    from trustroute.core.validation import check_keys, read_json

    path = Path(path)
    where = str(path)
    document = read_json(path, "policy file", fix="pass 'free', 'aware' or a file written by trustroute "
                         "synth --out")
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise InputError(where, "format", f"not a trustroute policy file (format {FORMAT!r} expected)",
                         "pass a file written by trustroute synth --out")
    joint = "kind" in document
    version = document.get("version")
    if (not (version in PLAIN_VERSIONS or (joint and version in JOINT_VERSIONS))
            or isinstance(version, bool)):
        older = ("; version 2 policies drive the state-only completion where they have no row, which "
                 "their bounds were certified for, not this trustroute's acting rule"
                 if version == 2 else "")
        raise InputError(where, "version", f"policy file version {str(version)[:30]}, this "
                         f"trustroute reads version {VERSION}{older}", "re-run trustroute synth")
    if joint and document["kind"] != JOINT_KIND:
        raise InputError(where, "kind", f"unknown policy kind {str(document['kind'])[:30]!r} "
                         f"(only {JOINT_KIND!r})", RESYNTH)
    check_keys(document, DOCUMENT_KEYS + (JOINT_KEYS if joint else ()), where, "", "policy file")
    for key in ("horizon", "guide_horizon") if joint else ("horizon",):
        _check_junction_count(document.get(key), key, where)
    for key in ("lower", "upper"):
        value = document.get(key)
        if value is not None and not (isinstance(value, int | float) and not isinstance(value, bool)
                                      and math.isfinite(value) and 0 <= value <= 1):
            raise InputError(where, key, f"{key} bound {str(value)[:30]} is not a probability", RESYNTH)
    if not isinstance(document.get("arrays"), str) or Path(document["arrays"]).name != document["arrays"]:
        raise InputError(where, "arrays", "must name the .npz file beside the policy file", RESYNTH)
    return document


def read_policy_table(arrays: Path, document: dict, town: Town, driver: DriverModel,
                      spec: Spec) -> PolicyTable | JointPolicyTable:
    """The decision table of a policy file, verified: the hash its JSON records, a readable .npz
    without pickles, the five arrays with consistent shapes and integer types, and every entry in
    range for this town, driver model and spec (InputError otherwise)."""
    from trustroute.core.validation import MAX_ARRAY_BYTES, read_input_bytes
    from trustroute.policies.logic.dfa import build_dfa

    where = str(arrays)
    if not arrays.exists():
        raise InputError(where, "arrays", "the policy's array file is missing",
                         "keep the .npz next to the policy file, or re-run trustroute synth")
    data = read_input_bytes(arrays, "policy array file", MAX_ARRAY_BYTES,
                            fix="keep the .npz next to the policy file, or re-run trustroute synth")
    if hashlib.sha256(data).hexdigest() != document.get("arrays_sha256"):
        raise InputError(where, "", "array file does not match its policy file (hash differs)", RESYNTH)
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            names = JOINT_ARRAY_NAMES if "kind" in document else ARRAY_NAMES
            if "kind" not in document and document.get("version", VERSION) >= 4:
                names = names + BOX_ARRAY_NAMES
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
    rows = arrays_read["t"].shape[0] if arrays_read["t"].ndim == 1 else -1
    joint = "joint" in arrays_read
    integers = ("t", "x", "q", "action") if joint else ("t", "x", "q", "projected", "action")
    _check_integers(arrays_read, integers, rows, where)
    beliefs = arrays_read["beliefs"]
    if beliefs.shape != (rows, driver.n_trust) or beliefs.dtype.kind != "f":
        raise InputError(where, "beliefs", f"beliefs have shape {beliefs.shape}, expected ({rows}, "
                         f"{driver.n_trust}) for this driver model", RESYNTH)
    if rows != document.get("rows"):
        raise InputError(where, "", f"{rows} rows but the policy file records {document.get('rows')}",
                         RESYNTH)
    t, x, q, action = (arrays_read[name].astype(np.int64) for name in ("t", "x", "q", "action"))
    projected = None if joint else arrays_read["projected"].astype(np.int64)
    n_q = build_dfa(spec).n_states
    n_p = state_only_task(town, spec).dfa.n_states
    extra = [] if projected is None else [("projected", ((projected < 0) | (projected >= n_p)).any(),
                                           f"state-only task states outside 0..{n_p - 1}")]
    _check_decisions(where, "", "decision table", t, x, q, action, town, n_q, extra)
    if (not np.isfinite(beliefs).all() or (beliefs < 0).any() or (beliefs > 1).any()
            or (np.abs(beliefs.sum(axis=1) - 1) > 1e-6).any()):
        raise InputError(where, "beliefs", "beliefs are not probability vectors", RESYNTH)
    if not joint:
        boxes = _box_rows(arrays_read, where, document, driver.n_trust, town, n_q)
        return PolicyTable(t=t, x=x, q=q, beliefs=beliefs, action=action, projected=projected,
                           boxes=boxes)
    table = arrays_read["joint"]
    if table.shape != (rows, driver.n_trust, n_q) or table.dtype.kind != "f":
        raise InputError(where, "joint", f"joint beliefs have shape {table.shape}, expected ({rows}, "
                         f"{driver.n_trust}, {n_q}) for this driver model and spec", RESYNTH)
    if (not np.isfinite(table).all() or (table < 0).any()
            or (np.abs(table.sum(axis=(1, 2)) - 1) > 1e-6).any()):
        raise InputError(where, "joint", "joint beliefs are not probability tables", RESYNTH)
    return JointPolicyTable(t=t, x=x, q=q, beliefs=beliefs, joint=table, action=action)


def _box_rows(arrays: dict, where: str, document: dict, n_trust: int, town: Town, n_q: int
              ) -> BoxRows | None:
    """The box rows of a version-4 table, verified like the exact rows (None: a version-3 file)."""
    if "box_t" not in arrays:
        return None
    rows = arrays["box_t"].shape[0] if arrays["box_t"].ndim == 1 else -1
    _check_integers(arrays, ("box_t", "box_x", "box_q", "box_action"), rows, where)
    for name in ("box_lo", "box_hi"):
        if arrays[name].shape != (rows, n_trust) or arrays[name].dtype.kind != "f":
            raise InputError(where, name, f"{name} has shape {arrays[name].shape}, expected "
                             f"({rows}, {n_trust}) for this driver model", RESYNTH)
    value = arrays["box_value"]
    if value.shape != (rows,) or value.dtype.kind != "f":
        raise InputError(where, "box_value", f"box_value has shape {value.shape}, expected ({rows},)",
                         RESYNTH)
    if rows != document.get("box_rows"):
        raise InputError(where, "box_rows", f"{rows} box rows but the policy file records "
                         f"{document.get('box_rows')}", RESYNTH)
    t, x, q, action = (arrays[name].astype(np.int64) for name in ("box_t", "box_x", "box_q", "box_action"))
    lo, hi = arrays["box_lo"], arrays["box_hi"]
    extra = [
        ("box_lo", not (np.isfinite(lo).all() and np.isfinite(hi).all()) or (lo < 0).any()
         or (hi > 1).any() or (lo > hi).any(), "boxes that are not within [0, 1] with lo <= hi"),
        ("box_value", not np.isfinite(value).all() or (value < 0).any() or (value > 1).any(),
         "values that are not probabilities"),
    ]
    _check_decisions(where, "box_", "box rows", t, x, q, action, town, n_q, extra)
    return BoxRows(t=t, x=x, q=q, lo=lo, hi=hi, value=value, action=action)


def _check_integers(arrays: dict, names: tuple[str, ...], rows: int, where: str) -> None:
    """InputError at the first of `names` that is not a 1-d integer array of `rows` entries."""
    for name in names:
        array = arrays[name]
        if array.ndim != 1 or array.shape[0] != rows or array.dtype.kind not in "iu":
            raise InputError(where, name, f"array '{name}' is not {max(rows, 0)} integers "
                             f"(shape {array.shape}, type {array.dtype})", RESYNTH)


def _check_decisions(where: str, prefix: str, what_rows: str, t: np.ndarray, x: np.ndarray, q: np.ndarray,
                     action: np.ndarray, town: Town, n_q: int, extra: list) -> None:
    """InputError at the first array (named with `prefix`) whose entries are out of range for this
    town and spec: junction counts, roads, DFA states, the `extra` (name, bad, what) checks, moves."""
    n_x = len(town.states)
    slots = np.array([len(town.actions(state)) for state in town.states], dtype=np.int64)
    problems = [
        (f"{prefix}t", (t < 0).any(), "negative junction counts"),
        (f"{prefix}x", ((x < 0) | (x >= n_x)).any(), f"roads outside 0..{n_x - 1}"),
        (f"{prefix}q", ((q < 0) | (q >= n_q)).any(), f"DFA states outside 0..{n_q - 1}"),
    ] + extra
    for name, bad, what in problems:
        if bad:
            raise InputError(where, name, f"{what_rows} has {what}", RESYNTH)
    if ((action < 0) | (action >= slots[x])).any():
        row = int(np.flatnonzero((action < 0) | (action >= slots[x]))[0])
        raise InputError(where, f"{prefix}action", f"{what_rows}, row {row}: action {int(action[row])} is "
                         f"not one of the {int(slots[x[row]])} moves from road {town.states[x[row]]}",
                         RESYNTH)


def load_policy(path: str | Path, town: Town, driver: DriverModel, spec: Spec
                ) -> BeliefTablePolicy | JointTablePolicy:
    """Load a policy file made for exactly this town, driver model and spec."""
    path = Path(path)
    where = str(path)
    document = read_policy_document(path)
    made_for_population = document.get("population_hash")
    if made_for_population is not None and getattr(driver, "population_hash", None) != made_for_population:
        raise InputError(where, "population_hash", "policy was synthesized for a driver population "
                         f"(hash {str(made_for_population)[:12]}...) that is not the one given",
                         "pass the driver population it was made for (--population), or re-run "
                         "trustroute synth --population for this one")
    if made_for_population is None and getattr(driver, "population_hash", ""):
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
    if isinstance(table, JointPolicyTable):
        from trustroute.policies.model.trust_pomdp import build_pomdp

        return JointTablePolicy(table, build_pomdp(town, driver), spec, document.get("guide_horizon"),
                                name=str(document.get("name", "aware")), lower=document.get("lower"),
                                upper=document.get("upper"), horizon=document.get("horizon"))
    return BeliefTablePolicy(table, town, spec, name=str(document.get("name", "aware")),
                             lower=document.get("lower"), upper=document.get("upper"),
                             horizon=document.get("horizon"),
                             reweight=prior_reweight(document, driver.n_trust, where))


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
    from trustroute.policies.belief.driver_types import lift_population, lift_spec

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
