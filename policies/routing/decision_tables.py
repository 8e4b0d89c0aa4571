"""The decision tables of synthesized policies as one family: kinds of rows, and the table kinds
built from them, in one registry (docs/formats/policy_file.md).

Row kinds (`RowKind`), each with its arrays in a policy file's `.npz` and their checks:
- `EXACT_ROWS`: (t, x, q, projected, beliefs, action), the product nodes the belief-MDP search
  expanded (policies/routing/aware_table.py, `PolicyTable`);
- `BOX_ROWS`: (box_t, box_x, box_q, box_lo, box_hi, box_value, box_action), a cluster policy's
  boxes (aware_table.BoxRows), from file version 4 on;
- `JOINT_ROWS`: (t, x, q, beliefs, action, joint), the joint-belief nodes of the trust-state search
  (policies/routing/trust_state_table.py, `JointPolicyTable`).

Table kinds (`TableKind`, `TABLE_KINDS`): which rows a table has, the file versions that hold it,
its acting rule in words, the document keys it adds and the routing policy that acts on it.
`PLAIN_TABLE` (files without `kind`) holds exact rows and box rows; `JOINT_TABLE`
(`kind = "joint-belief"`) holds joint rows, of one driver model or of a driver population's
type-aware model (then with the population keys and the type prior its table was made for).
`table_kind(table)` and `document_table_kind(document)` find a kind by the table's type or the
document's `kind`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.validation import first_non_belief
from trustroute.core.wording import shown_value
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.aware_table import BeliefTablePolicy, BoxRows, PolicyTable
from trustroute.policies.routing.fallback import FallbackPolicy
from trustroute.policies.routing.free import state_only_task
from trustroute.policies.routing.protocol import Certificate, RoutingPolicy
from trustroute.policies.routing.trust_state_table import JointPolicyTable, JointTablePolicy

RESYNTH = "re-run trustroute synth to write both files again"

TableT = TypeVar("TableT")
PolicyT = TypeVar("PolicyT", bound=RoutingPolicy)


@dataclass(frozen=True, eq=False)
class ReadContext:
    """What a table's arrays are checked against: the file, its document, the town, driver, spec."""

    where: str
    document: dict
    town: Town
    driver: DriverModel
    spec: Spec
    n_q: int                 # DFA states of the spec


@dataclass(frozen=True, eq=False)
class RowKind:
    """One kind of decision rows: its arrays in file order ((array name, attribute) pairs) and the
    reader that checks them and builds the rows."""

    name: str
    columns: tuple[tuple[str, str], ...]
    read: Callable[[dict, ReadContext], object]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.columns)

    def arrays(self, rows) -> dict[str, np.ndarray]:
        return {name: getattr(rows, attribute) for name, attribute in self.columns}


def check_integers(arrays: dict, names: tuple[str, ...], rows: int, where: str) -> None:
    """InputError at the first of `names` that is not a 1-d integer array of `rows` entries."""
    for name in names:
        array = arrays[name]
        if array.ndim != 1 or array.shape[0] != rows or array.dtype.kind not in "iu":
            raise InputError(where, name, f"array '{name}' is not {max(rows, 0)} integers "
                             f"(shape {array.shape}, type {array.dtype})", RESYNTH)


def check_decisions(context: ReadContext, prefix: str, what_rows: str, t: np.ndarray, x: np.ndarray,
                    q: np.ndarray, action: np.ndarray, extra: list) -> None:
    """InputError at the first array (named with `prefix`) whose entries are out of range for the
    context's town and spec: junction counts, roads, DFA states, the `extra` (name, bad, what)
    checks, moves."""
    where, town, n_q = context.where, context.town, context.n_q
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


def read_node_rows(arrays: dict, context: ReadContext, integers: tuple[str, ...],
                   extra: Callable[[dict], list]) -> tuple[int, dict]:
    """The checks exact and joint rows share: integer columns, beliefs [rows, n_trust] that are
    probability vectors, the row count the document records, every decision in range (and the
    `extra` checks of the decoded integer columns). (rows, decoded integer columns)."""
    where, n_trust = context.where, context.driver.n_trust
    rows = arrays["t"].shape[0] if arrays["t"].ndim == 1 else -1
    check_integers(arrays, integers, rows, where)
    beliefs = arrays["beliefs"]
    if beliefs.shape != (rows, n_trust) or beliefs.dtype.kind != "f":
        raise InputError(where, "beliefs", f"beliefs have shape {beliefs.shape}, expected ({rows}, "
                         f"{n_trust}) for this driver model", RESYNTH)
    if rows != context.document.get("rows"):
        raise InputError(where, "", f"{rows} rows but the policy file records "
                         f"{context.document.get('rows')}", RESYNTH)
    decoded = {name: arrays[name].astype(np.int64) for name in integers}
    check_decisions(context, "", "decision table", decoded["t"], decoded["x"], decoded["q"],
                    decoded["action"], extra(decoded))
    if first_non_belief(beliefs) is not None:
        raise InputError(where, "beliefs", "beliefs are not probability vectors", RESYNTH)
    return rows, decoded


def read_exact_rows(arrays: dict, context: ReadContext) -> PolicyTable:
    """Exact rows, checked; the state-only task states in range of the spec's task."""
    n_p = state_only_task(context.town, context.spec).dfa.n_states
    _, decoded = read_node_rows(
        arrays, context, ("t", "x", "q", "projected", "action"),
        lambda d: [("projected", ((d["projected"] < 0) | (d["projected"] >= n_p)).any(),
                    f"state-only task states outside 0..{n_p - 1}")])
    return PolicyTable(t=decoded["t"], x=decoded["x"], q=decoded["q"], beliefs=arrays["beliefs"],
                       action=decoded["action"], projected=decoded["projected"])


def read_joint_rows(arrays: dict, context: ReadContext) -> JointPolicyTable:
    """Joint rows, checked; J [rows, n_trust, n_q] a probability table per row."""
    where, n_trust = context.where, context.driver.n_trust
    rows, decoded = read_node_rows(arrays, context, ("t", "x", "q", "action"), lambda d: [])
    table = arrays["joint"]
    if table.shape != (rows, n_trust, context.n_q) or table.dtype.kind != "f":
        raise InputError(where, "joint", f"joint beliefs have shape {table.shape}, expected ({rows}, "
                         f"{n_trust}, {context.n_q}) for this driver model and spec", RESYNTH)
    if (not np.isfinite(table).all() or (table < 0).any()
            or (np.abs(table.sum(axis=(1, 2)) - 1) > 1e-6).any()):
        raise InputError(where, "joint", "joint beliefs are not probability tables", RESYNTH)
    return JointPolicyTable(t=decoded["t"], x=decoded["x"], q=decoded["q"], beliefs=arrays["beliefs"],
                            joint=table, action=decoded["action"])


def read_box_rows(arrays: dict, context: ReadContext) -> BoxRows:
    """Box rows, checked like the exact rows; boxes within [0, 1], values probabilities."""
    where, n_trust, document = context.where, context.driver.n_trust, context.document
    rows = arrays["box_t"].shape[0] if arrays["box_t"].ndim == 1 else -1
    check_integers(arrays, ("box_t", "box_x", "box_q", "box_action"), rows, where)
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
    check_decisions(context, "box_", "box rows", t, x, q, action, extra)
    return BoxRows(t=t, x=x, q=q, lo=lo, hi=hi, value=value, action=action)


EXACT_ROWS = RowKind("exact", (("t", "t"), ("x", "x"), ("q", "q"), ("projected", "projected"),
                               ("beliefs", "beliefs"), ("action", "action")), read_exact_rows)
BOX_ROWS = RowKind("box", (("box_t", "t"), ("box_x", "x"), ("box_q", "q"), ("box_lo", "lo"),
                           ("box_hi", "hi"), ("box_value", "value"), ("box_action", "action")),
                   read_box_rows)
JOINT_ROWS = RowKind("joint", (("t", "t"), ("x", "x"), ("q", "q"), ("beliefs", "beliefs"),
                               ("action", "action"), ("joint", "joint")), read_joint_rows)


@dataclass(frozen=True, eq=False)
class PolicyOrigin:
    """What a loaded table's policy is built with besides the table: the file's document and the
    problem it was made for."""

    document: dict
    town: Town
    driver: DriverModel
    spec: Spec
    reweight: np.ndarray | None


@dataclass(frozen=True, eq=False)
class TableKind(Generic[TableT, PolicyT]):
    """A kind of decision table: its row kinds (with the first file version holding each), how a
    table splits into them and is joined back, the file versions it is read from, its acting rule
    in words, the document keys it adds, and the routing policy acting on it."""

    kind: str | None                         # the document's `kind` (None: no such key)
    table_type: type[TableT]
    blocks: tuple[tuple[RowKind, int], ...]
    versions: tuple[int, ...]
    acting_rule: str
    keys: tuple[str, ...]
    split: Callable[[TableT], tuple]
    join: Callable[[tuple], TableT]
    document: Callable[[PolicyT], dict]
    policy: Callable[[TableT, PolicyOrigin], PolicyT]
    check: Callable[[dict, str], None]
    fallback: str = ""                       # what drives wherever the table has no row

    def block_names(self, version: int) -> tuple[str, ...]:
        """The arrays a file of `version` holds."""
        return tuple(name for rows, since in self.blocks if version >= since for name in rows.names)

    def arrays(self, table: TableT) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for (rows_kind, _), rows in zip(self.blocks, self.split(table), strict=True):
            out.update(rows_kind.arrays(rows))
        return out

    def read(self, arrays: dict, version: int, context: ReadContext) -> TableT:
        """The table from a file's arrays, each block checked in order (a block a file of `version`
        does not hold is None)."""
        return self.join(tuple(rows_kind.read(arrays, context) if version >= since else None
                               for rows_kind, since in self.blocks))


PLAIN_ACTING_RULE = (
    "action of the stored row with the same (junctions driven, road, DFA state, state-only "
    "task state) whose belief is within 1e-12 of the AV's (the synthesis visited it); "
    "else, among the box rows of the same (junctions driven, road, DFA state) whose box "
    "holds the AV's belief, the action of the one of the largest value; "
    "else the move of the free completion: the trust-free shortest completion of the "
    "state-only task while it is not complete, then the shortest route back to what the "
    "DFA still needs, every label allowed (the first legal move where acceptance is "
    "unreachable)")
JOINT_ACTING_RULE = ("action of the stored row with the same (junctions driven, road) whose (joint "
                     "belief, belief) is within 1e-9 (Euclidean); else the successor with the largest "
                     "relaxed action value at the joint belief (policies/belief/trust_state_relaxation.py)")


def plain_split(table: PolicyTable) -> tuple[PolicyTable, BoxRows]:
    return table, table.boxes if table.boxes is not None else BoxRows.empty(table.beliefs.shape[1])


def plain_join(blocks: tuple) -> PolicyTable:
    exact, boxes = blocks
    return PolicyTable(t=exact.t, x=exact.x, q=exact.q, beliefs=exact.beliefs, action=exact.action,
                       projected=exact.projected, boxes=boxes)


def plain_policy(table: PolicyTable, origin: PolicyOrigin) -> BeliefTablePolicy:
    document = origin.document
    return BeliefTablePolicy(table, origin.town, origin.spec, name=str(document.get("name", "aware")),
                             lower=document.get("lower"), upper=document.get("upper"),
                             horizon=document.get("horizon"), reweight=origin.reweight)


def joint_policy(table: JointPolicyTable, origin: PolicyOrigin) -> JointTablePolicy:
    """The policy of joint rows (a population's: reweighted to the type prior its file records)."""
    document = origin.document
    certificate = Certificate(document.get("lower"), document.get("upper"), document.get("horizon"))
    return JointTablePolicy(table, build_pomdp(origin.town, origin.driver), origin.spec,
                            document.get("guide_horizon"), name=str(document.get("name", "aware")),
                            certificate=certificate, reweight=origin.reweight)


def check_junction_count(value: object, key: str, where: str) -> None:
    """A horizon of the header: a junction count from 0 to 10 000, or null (unbounded)."""
    count = isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 10_000
    if not (value is None or count):
        raise InputError(where, key, f"{key.replace('_', ' ')} {shown_value(value, 30)} is not a junction "
                         "count or null", RESYNTH)


def check_guide_horizon(document: dict, where: str) -> None:
    check_junction_count(document.get("guide_horizon"), "guide_horizon", where)


# Version 3: where a plain policy has no row it drives the free completion of (road, DFA state,
# task state); version 2 plain files were synthesized for the state-only completion (then the first
# legal move) and are refused: their certified L is not the value of the version-3 rule. Version 4
# adds the box rows (possibly empty); a version 3 file is read without them, which the version 4
# rule treats exactly as version 3 did. Joint files (their rule does not use the completion) are
# read from version 2 on.
PLAIN_TABLE: TableKind[PolicyTable, BeliefTablePolicy] = TableKind(
    kind=None, table_type=PolicyTable, blocks=((EXACT_ROWS, 3), (BOX_ROWS, 4)), versions=(3, 4),
    acting_rule=PLAIN_ACTING_RULE, keys=(), split=plain_split, join=plain_join,
    document=lambda policy: {}, policy=plain_policy, check=lambda document, where: None,
    fallback="the free completion (the trust-free shortest completion of the spec's state-only task)")
JOINT_TABLE: TableKind[JointPolicyTable, JointTablePolicy] = TableKind(
    kind="joint-belief", table_type=JointPolicyTable, blocks=((JOINT_ROWS, 2),), versions=(2, 3, 4),
    acting_rule=JOINT_ACTING_RULE, keys=("kind", "guide_horizon"), split=lambda table: (table,),
    join=lambda blocks: blocks[0],
    document=lambda policy: {"kind": "joint-belief", "guide_horizon": policy.guide_horizon},
    policy=joint_policy, check=check_guide_horizon,
    fallback="the relaxed guide (the successor of the largest relaxed action value)")
# The kinds differ in their table and policy types: a kind found at run time is read as any kind.
TABLE_KINDS: tuple[TableKind[Any, Any], ...] = (PLAIN_TABLE, JOINT_TABLE)


def table_kind(table) -> TableKind[Any, Any]:
    """The kind of a decision table, by its type."""
    for kind in TABLE_KINDS:
        if type(table) is kind.table_type:
            return kind
    raise ValueError(f"no policy file kind holds a {type(table).__name__}")


def document_table_kind(document: dict) -> TableKind[Any, Any] | None:
    """The kind a policy document names (None: a `kind` no table kind has)."""
    for kind in TABLE_KINDS:
        if document.get("kind") == kind.kind and ("kind" in document) == (kind.kind is not None):
            return kind
    return None


def fallback_only(policy: RoutingPolicy) -> str | None:
    """What drives everywhere when `policy` (or the policy inside the study's fallback wrapper) is a
    synthesized table without a single decision row, exact or box: then nothing synthesized acts
    and the policy is its table kind's fallback, which is returned in words. None for a table with
    rows and for any other policy (the trust-free one is not a synthesis result)."""
    if isinstance(policy, FallbackPolicy):
        return fallback_only(policy.inner)
    if not isinstance(policy, BeliefTablePolicy | JointTablePolicy):
        return None
    table = policy.table
    kind = next((k for k in TABLE_KINDS if type(table) is k.table_type), None)
    if kind is None:
        return None
    box_rows = table.boxes.rows if isinstance(table, PolicyTable) and table.boxes is not None else 0
    return kind.fallback if table.rows == 0 and box_rows == 0 else None


def fallback_warning(what: str, fallback: str, converged: bool, outranked: bool = False) -> str:
    """The one line that says a synthesis returned only its fallback (`fallback_only`);
    `outranked`: synthesized candidates with rows were valued and none was worth more (a robust
    synthesis keeps the candidate with the best worst type, the fallback among them)."""
    if converged:
        why = "the search proved it within tau of the optimum"
    elif outranked:
        why = ("no synthesized candidate was worth more for its worst type, so L is a lower bound of "
               "the fallback's worst type (raise --time-limit, or --work-limit where one is set, for "
               "candidates searched further)")
    else:
        why = ("nothing was synthesized in time, so L is only a lower bound of the fallback's value, "
               "0 if the search stopped before valuing it (trustroute evaluate values it exactly; "
               "raise --time-limit, or --work-limit where one is set)")
    return (f"warning: {what} has no synthesized decision (0 rows): it is only its fallback, "
            f"{fallback}; {why}")
