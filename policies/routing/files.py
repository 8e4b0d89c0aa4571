"""Policy files: a synthesized policy on disk, bound to the town, driver model and spec it was made for.

`save_policy(result, path, town, driver, spec)` writes `path` (JSON: format, content hashes of
town, driver model and spec, horizon, belief rule, bounds, the acting rule in words, and the name
and SHA-256 of the array file) and `path` with suffix `.npz` (the decision table of
policies.table_policy: t, x, q, beliefs, action). `load_policy(path, town, driver, spec)` checks
the format and all three hashes and raises InputError naming the file and the fix on a mismatch.
Every key: docs/formats/policy_file.md.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from trustroute.networks.errors import InputError
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.aware_table import BeliefTablePolicy, PolicyTable

FORMAT = "trustroute-policy"
VERSION = 1
ACTING_RULE = ("action of the stored row with the same (junctions driven, road, DFA state) whose belief "
               "is nearest (Euclidean); else the nearest row with the same (road, DFA state) at any "
               "junction count; else the trust-free shortest completion of the state-only task")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def array_path(path: str | Path) -> Path:
    return Path(path).with_suffix(".npz")


def save_policy(result, path: str | Path, town: Town, driver: DriverModel, spec: Spec) -> Path:
    """Write the policy of a SynthesisResult to `path` (+ `.npz`); returns the JSON path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    table: PolicyTable = result.policy.table
    arrays = array_path(path)
    with arrays.open("wb") as handle:
        np.savez_compressed(handle, t=table.t, x=table.x, q=table.q, beliefs=table.beliefs,
                            action=table.action)
    document = {
        "format": FORMAT,
        "version": VERSION,
        "name": "aware",
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
        "acting_rule": ACTING_RULE,
        "arrays": arrays.name,
        "arrays_sha256": _sha256(arrays),
    }
    path.write_text(json.dumps(document, indent=1) + "\n")
    return path


def read_policy_document(path: str | Path) -> dict:
    """The JSON part of a policy file, checked for format (InputError otherwise)."""
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise InputError(where, "", "policy file not found",
                         "pass 'free', 'aware' or a file written by trustroute synth --out")
    try:
        document = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(where, "", f"not a JSON policy file ({exc})",
                         "pass a file written by trustroute synth --out") from None
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise InputError(where, "format", f"not a trustroute policy file (format {FORMAT!r} expected)",
                         "pass a file written by trustroute synth --out")
    if document.get("version") != VERSION:
        raise InputError(where, "version", f"policy file version {document.get('version')!r}, this "
                         f"trustroute reads version {VERSION}", "re-run trustroute synth")
    return document


def load_policy(path: str | Path, town: Town, driver: DriverModel, spec: Spec) -> BeliefTablePolicy:
    """Load a policy file made for exactly this town, driver model and spec."""
    path = Path(path)
    where = str(path)
    document = read_policy_document(path)
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
    arrays = path.parent / str(document.get("arrays", ""))
    if not arrays.is_file():
        raise InputError(where, "arrays", f"array file {arrays} is missing",
                         "keep the .npz next to the policy file, or re-run trustroute synth")
    if _sha256(arrays) != document.get("arrays_sha256"):
        raise InputError(str(arrays), "", "array file does not match its policy file (hash differs)",
                         "re-run trustroute synth to write both files again")
    with np.load(arrays) as data:
        table = PolicyTable(t=data["t"], x=data["x"], q=data["q"], beliefs=data["beliefs"],
                            action=data["action"])
    n_x = len(town.states)
    if table.rows and (table.x.max() >= n_x or table.beliefs.shape[1] != driver.n_trust):
        raise InputError(str(arrays), "", "decision table does not fit this town and driver model",
                         "re-run trustroute synth")
    return BeliefTablePolicy(table, town, spec, name=str(document.get("name", "aware")),
                             lower=document.get("lower"), upper=document.get("upper"),
                             horizon=document.get("horizon"))
