"""scLDTL spec files: TOML schema, validation (optionally against a town), identity, projection.

A spec file (e.g. specs/phi1.toml) has `name`, `start` (directed road "U-V", position 0),
`formula` (policies/logic/formula.py grammar), a `[states]` table (atom -> list of directed roads,
or a selector `{junction = "J12"}` / `{street = "Main Street"}` that a town resolves to roads) and
`[beliefs.NAME]` tables with `coeffs` (one per trust level of the driver model; the default model
has 7; `load_spec` given the model's trust levels, as every command calls it, checks the length) and
`offset`: a belief atom is true iff `offset - coeffs·b < 0` (strict; docs/model.md, "scLDTL"; every
key: docs/formats/spec.md), and a `[trust_states]` table of trust-state atoms `NAME = { roads =
[...], trust = [6, 7] }`: true at a position iff the road is one of `roads` (any road when `roads`
is absent) and the human's hidden trust is one of the levels `trust` (docs/trust_states.md), and a
`[type_beliefs]` table of type-belief atoms `NAME = { types = ["flat"], above = 0.7 }`: true iff the
AV's belief that the driver is of one of `types` exceeds `above` (strict; the types of a driver
population, docs/driver_types.md). Every error is an InputError naming the file, line and column.
"""

from __future__ import annotations

import functools
import hashlib
import json
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypedDict, TypeVar

from trustroute.core.errors import InputError
from trustroute.core.fields import (
    EMPTY,
    Field,
    FieldTable,
    Integer,
    Kind,
    ListOf,
    Number,
    Table,
    Text,
    check_fields,
    check_value,
    field_table,
    keys,
)
from trustroute.core.packaged import SPECS
from trustroute.core.validation import FILE_NAME, FILE_NAME_RULE, parse_toml, read_text
from trustroute.core.wording import counted, shown_value
from trustroute.networks.town import Town
from trustroute.policies.logic.formula import (
    ATOM_PATTERN,
    FALSE,
    KEYWORDS,
    TRUE,
    Formula,
    Literal,
    atoms_in_order,
    format_formula,
    map_literals,
    parse_formula,
)
from trustroute.policies.logic.road_selectors import selected_roads, unknown_spec_road_fix

N_TRUST_LEVELS = 7  # the Muir scale 1..7 of the default driver model (any number >= 2 is accepted)
# The parser and DFA construction recurse over the formula; these limits keep them far from
# Python's recursion limit while allowing any task a person would write.
MAX_FORMULA_CHARS = 20_000
MAX_FORMULA_NESTING = 100
MAX_ATOMS = 200
MAX_STATE_ROADS = 10_000


@dataclass(frozen=True)
class BeliefAtom:
    """True iff offset - coeffs·b < 0 (strict)."""

    coeffs: tuple[float, ...]
    offset: float


@dataclass(frozen=True)
class TrustStateAtom:
    """True at (x, θ) iff θ is in `trust` (levels 1..7) and, when `roads` is given, x is in it."""

    trust: frozenset[int]
    roads: frozenset[str] | None = None

    def holds_on_road(self, road: str) -> bool:
        return self.roads is None or road in self.roads


@dataclass(frozen=True)
class TypeBeliefAtom:
    """True iff the AV's belief that the driver's type is one of `types` exceeds `above` (strict):
    a belief atom on the type marginal (docs/driver_types.md, "Type-belief atoms")."""

    types: tuple[str, ...]
    above: float


@dataclass(frozen=True, eq=False)
class Spec:
    name: str
    start: str
    formula_text: str
    formula: Formula
    state_atoms: dict[str, frozenset[str]]
    belief_atoms: dict[str, BeliefAtom]
    source_path: str = ""
    trust_atoms: dict[str, TrustStateAtom] = field(default_factory=dict)
    type_atoms: dict[str, TypeBeliefAtom] = field(default_factory=dict)
    # The spec compiled on the towns it is checked against (town content hash -> CompiledSpec),
    # built by policies/logic/compiled.py's compile_spec and held here, so every reader of this
    # spec shares one DFA, labeller and state-only task.
    compilations: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @functools.cached_property
    def content_hash(self) -> str:
        """SHA-256 of the meaning (start, parsed formula, atom definitions), not name or formatting.
        Trust-state atoms enter only when there are some, so older specs keep their hashes."""
        meaning: dict = {
            "start": self.start,
            "formula": format_formula(self.formula),
            "states": {k: sorted(v) for k, v in sorted(self.state_atoms.items())},
            "beliefs": {k: {"coeffs": [float(c) for c in v.coeffs], "offset": float(v.offset)}
                        for k, v in sorted(self.belief_atoms.items())},
        }
        if self.trust_atoms:
            meaning["trust_states"] = {
                k: {"trust": sorted(v.trust), "roads": None if v.roads is None else sorted(v.roads)}
                for k, v in sorted(self.trust_atoms.items())}
        if self.type_atoms:
            meaning["type_beliefs"] = {k: {"types": sorted(v.types), "above": float(v.above)}
                                       for k, v in sorted(self.type_atoms.items())}
        canonical = json.dumps(
            meaning,
            sort_keys=True,
            separators=(",", ":"),
        )
        return hashlib.sha256(canonical.encode()).hexdigest()

    @property
    def atoms(self) -> tuple[str, ...]:
        """Every defined atom: state atoms sorted, then belief atoms sorted, then trust-state atoms,
        then type-belief atoms."""
        return (tuple(sorted(self.state_atoms)) + tuple(sorted(self.belief_atoms))
                + tuple(sorted(self.trust_atoms)) + tuple(sorted(self.type_atoms)))

    # Cached like content_hash (the spec is frozen): every episode asks, and each answer walks the formula.
    @functools.cached_property
    def uses_trust_atoms(self) -> bool:
        """True iff the formula tests the hidden trust (then the DFA state is partly hidden)."""
        return any(atom in self.trust_atoms for atom in self.formula_atoms)

    @functools.cached_property
    def formula_atoms(self) -> tuple[str, ...]:
        """Atoms the formula uses, in order of first occurrence."""
        return atoms_in_order(self.formula)


# -- locating things in the TOML text (for error messages) ------------------------------------------

def _locate(text: str, *needles: str) -> tuple[int, int] | None:
    """(line, column), 1-based, of the last needle, found in order line by line; None if absent."""
    lines = text.splitlines()
    row = 0
    found = None
    for needle in needles:
        pattern = re.compile(needle)
        for r in range(row, len(lines)):
            match = pattern.search(lines[r])
            if match:
                skipped = len(match.group()) - len(match.group().lstrip())
                found = (r + 1, match.start() + skipped + 1)
                row = r
                break
        else:
            return found
    return found


def _place(text: str, label: str, *needles: str) -> str:
    found = _locate(text, *needles)
    return f"line {found[0]} column {found[1]} ({label})" if found else label


def _formula_position(text: str) -> tuple[int, int]:
    """Line and column of the first character inside the formula string (best effort)."""
    for number, line in enumerate(text.splitlines(), start=1):
        match = re.match(r"\s*formula\s*=\s*(\"\"\"|'''|\"|')", line)
        if match:
            return number, match.end() + 1
    return 1, 1


# -- loading --------------------------------------------------------------------------------------
# Every key of a spec file and of its atoms (docs/formats/spec.md); the rules below check what a
# table cannot (name and formula limits, roads of the town, atom names unique across tables).

TRUST_STATE_EXAMPLE = "write [trust_states] then trusting = { roads = [\"K-L\"], trust = [6, 7] }"
TYPE_BELIEF_EXAMPLE = 'write [type_beliefs] then nontruster = { types = ["flat"], above = 0.7 }'


def _string(key: str) -> Field:
    return Field(key=key, kind=Text(nonempty=False), required=True, problem=f"'{key}' must be a string",
                 fix=f'write {key} = "..."', missing_fix=f'add {key} = "..." at the top of the file (see '
                 f'{SPECS.path("phi1") or "the packaged specs"})')


class SpecValues(TypedDict):
    """A spec file's checked values (FIELDS)."""

    name: str
    start: str
    formula: str
    states: Mapping[str, object]
    beliefs: Mapping[str, object]
    trust_states: Mapping[str, object]
    type_beliefs: Mapping[str, object]


class BeliefAtomValues(TypedDict):
    """A `[beliefs.NAME]` table's checked values (BELIEF_FIELDS)."""

    coeffs: list[float]
    offset: float


class TrustStateAtomValues(TypedDict):
    """A trust-state atom's checked values (TRUST_STATE_FIELDS)."""

    roads: list[str] | None
    trust: list[int]


class TypeBeliefAtomValues(TypedDict):
    """A type-belief atom's checked values (TYPE_BELIEF_FIELDS)."""

    types: list[str]
    above: float


AtomValues = TypeVar("AtomValues")  # the checked values of one inline atom table


FIELDS = field_table(
    SpecValues,
    _string("name"),
    _string("start"),
    _string("formula"),
    Field(key="states", kind=Table(), default=EMPTY, problem="'states' must be a table of atom -> roads",
          fix='write [states] then v1 = ["B-G", "F-G"]'),
    Field(key="beliefs", kind=Table(), default=EMPTY, problem="'beliefs' must be a table of tables",
          fix="write [beliefs.NAME] with coeffs = [...] and offset = ..."),
    Field(key="trust_states", kind=Table(), default=EMPTY,
          problem="'trust_states' must be a table of atom -> { roads, trust }", fix=TRUST_STATE_EXAMPLE),
    Field(key="type_beliefs", kind=Table(), default=EMPTY,
          problem="'type_beliefs' must be a table of atom -> { types, above }", fix=TYPE_BELIEF_EXAMPLE),
)
TOP_LEVEL_KEYS: tuple[str, ...] = keys(FIELDS)
STATE_ROADS = ListOf(item=Text(nonempty=False), max_items=MAX_STATE_ROADS)


def _belief_key(key: str, kind: Kind[object], problem: str, fix: str) -> Field:
    return Field(key=key, kind=kind, required=True, fix=fix,
                 problem=lambda seen: f"belief atom '{seen.owner}': {problem}",
                 missing=lambda seen: f"belief atom '{seen.owner}' is missing '{key}'",
                 missing_fix=lambda seen: f"add {key} = ... under [beliefs.{seen.owner}]")


BELIEF_FIELDS = field_table(
    BeliefAtomValues,
    _belief_key("coeffs", ListOf(item=Number()), "coeffs must be a list of finite numbers",
                "write coeffs = [1, 0, 0, 0, 0, 0, 0]"),
    _belief_key("offset", Number(), "offset must be a finite number", "write offset = 0.5"),
)


def _inline_key(noun: str, key: str, kind: Kind[object], problem: str, fix: str, example: str,
                required: bool = True) -> Field:
    return Field(key=key, kind=kind, required=required, fix=fix,
                 problem=lambda seen: f"{noun} atom '{seen.owner}': {problem}",
                 missing=lambda seen: f"{noun} atom '{seen.owner}' is missing '{key}'", missing_fix=example)


TRUST_STATE_FIELDS = field_table(
    TrustStateAtomValues,
    _inline_key("trust-state", "roads", ListOf(item=Text(nonempty=False)),
                "roads must be a list of directed roads",
                'write roads = ["U-V", ...] or leave it out for any road', TRUST_STATE_EXAMPLE,
                required=False),
    _inline_key("trust-state", "trust", ListOf(item=Integer(minimum=1, maximum=N_TRUST_LEVELS), min_items=1),
                f"trust must be a non-empty list of trust levels (integers 1..{N_TRUST_LEVELS})",
                "write trust = [6, 7]", TRUST_STATE_EXAMPLE),
)
TYPE_BELIEF_FIELDS = field_table(
    TypeBeliefAtomValues,
    _inline_key("type-belief", "types", ListOf(item=Text(), min_items=1, distinct=True),
                "types must be a non-empty list of distinct type names", 'write types = ["flat"]',
                TYPE_BELIEF_EXAMPLE),
    _inline_key("type-belief", "above", Number(minimum=0.0, maximum=1.0, open_above=True),
                "above must be a number in [0, 1)",
                "write above = 0.7 (the atom is true iff P(type in types) > above)", TYPE_BELIEF_EXAMPLE),
)


@dataclass(frozen=True)
class _SpecSource:
    """A spec's text and the name it is shown by: errors placed at a line and column."""

    text: str
    source: str

    def place(self, label: str, *needles: str) -> str:
        return _place(self.text, label, *needles)

    def error(self, label: str, needles: tuple[str, ...], problem: str, fix: str) -> InputError:
        return InputError(self.source, self.place(label, *needles), problem, fix)

    def belief_place(self, atom: str, key: str | None = None) -> str:
        """Where the table `[beliefs.ATOM]` is written, or its `key` in it (the line of `key = ...`)."""
        return self.place(f"beliefs.{atom}", rf"^\s*\[beliefs\.{re.escape(atom)}\]",
                          *((rf"^\s*{re.escape(key)}\s*=",) if key is not None else ()))

    def key_place(self, key: str) -> str:
        """Where a top-level key (or table) is written."""
        return self.place(key, rf"^\s*\[?{re.escape(key)}\b")

    def check_atom_name(self, atom: str, table: str) -> None:
        if not ATOM_PATTERN.fullmatch(atom) or atom in KEYWORDS:
            raise self.error(f"{table}.{atom}", (re.escape(atom),), f"'{atom}' is not a valid atom name",
                             "use letters, digits and '_' (not starting with a digit), and not "
                             + ", ".join(sorted(KEYWORDS)))


def _paren_depth(text: str) -> int:
    depth = deepest = 0
    for char in text:
        if char == "(":
            depth += 1
            deepest = max(deepest, depth)
        elif char == ")":
            depth -= 1
    return deepest


def _check_name(name: str, spec: _SpecSource) -> None:
    """Non-blank, and safe as a file name (it names cache entries)."""
    needles = (r"^\s*name\s*=",)
    if not name.strip():
        raise spec.error("name", needles, "'name' is empty", 'write name = "phi1"')
    if not FILE_NAME.fullmatch(name):
        raise spec.error("name", needles, f"spec name {shown_value(name)} "
                         f"is not {FILE_NAME_RULE} (it names cache files)",
                         'write e.g. name = "phi1"')


def _check_formula_size(formula_text: str, spec: _SpecSource) -> None:
    """Short and shallow enough for the recursive parser and DFA construction."""
    needles = (r"^\s*formula\s*=",)
    if len(formula_text) > MAX_FORMULA_CHARS:
        raise spec.error("formula", needles, f"the formula has {len(formula_text)} characters "
                         f"(the limit is {MAX_FORMULA_CHARS})", "split the task or simplify the formula")
    nesting = _paren_depth(formula_text)
    if nesting > MAX_FORMULA_NESTING:
        raise spec.error("formula", needles, f"the formula nests parentheses {nesting} deep "
                         f"(the limit is {MAX_FORMULA_NESTING})", "simplify the formula")


def _check_roads(roads: list[str], owner: str, place: Callable[[str], str], source: str,
                 town: Town | None) -> None:
    """Every road a directed road "U-V" (of `town` when given); `owner` names the atom."""
    for road in roads:
        if "-" not in road:
            raise InputError(source, place(road), f"'{road}' is not a directed road \"U-V\"",
                             "write roads as \"U-V\"")
        if town is not None and road not in town.states:
            raise InputError(source, place(road), f"{owner}: '{road}' is not a directed road of the town "
                             f"({town.source_path or 'given town'})",
                             unknown_spec_road_fix(town, road))


def _state_atoms(raw: Mapping[str, object], spec: _SpecSource,
                 town: Town | None) -> dict[str, frozenset[str]]:
    """The `[states]` table: atom -> list of directed roads, or a selector naming them by junction
    or street. Checked in the file's order, so the first error reported is the first in the file;
    kept sorted by name."""
    atoms: dict[str, frozenset[str]] = {}
    for atom in raw:
        spec.check_atom_name(atom, "states")
        label = f"states.{atom}"
        needles = (r"^\s*\[states\]", rf"^\s*{re.escape(atom)}\s*=")
        entry = raw[atom]
        if isinstance(entry, dict):
            atoms[atom] = frozenset(selected_roads(entry, atom, spec.place(label, *needles),
                                                    spec.source, town))
            continue
        roads = check_value(entry, STATE_ROADS, spec.source, spec.place(label, *needles),
                            f"state atom '{atom}' must be a list of directed roads",
                            f'write {atom} = ["U-V", ...], or {{junction = "J"}} or {{street = "Name"}}')

        def road_place(road: str, needles: tuple[str, ...] = needles, label: str = label) -> str:
            return spec.place(label, *needles, re.escape(f'"{road}"'))

        _check_roads(roads, f"state atom '{atom}'", road_place, spec.source, town)
        atoms[atom] = frozenset(roads)
    return dict(sorted(atoms.items()))


def _belief_atoms(raw: Mapping[str, object], spec: _SpecSource, taken: set[str]) -> dict[str, BeliefAtom]:
    """The `[beliefs.NAME]` tables: coeffs (one per trust level, at least 2) and offset. Checked in
    the file's order and kept sorted by name, as `[states]`."""
    atoms: dict[str, BeliefAtom] = {}
    for atom in raw:
        spec.check_atom_name(atom, "beliefs")
        entry = raw[atom]
        if atom in taken:
            raise InputError(spec.source, spec.belief_place(atom), f"atom '{atom}' is defined both under "
                             "[states] and [beliefs]", "rename one of them")
        if not isinstance(entry, dict):
            raise InputError(spec.source, spec.belief_place(atom), f"belief atom '{atom}' must be a table",
                             f"write [beliefs.{atom}] with coeffs = [...] and offset = ...")

        def place(key: str, atom: str = atom, entry: dict = entry) -> str:
            return spec.belief_place(atom, key if key in entry else None)

        values = check_fields(entry, BELIEF_FIELDS, spec.source, f"belief atom '{atom}'", place, owner=atom)
        coeffs = values["coeffs"]
        if len(coeffs) < 2:
            raise InputError(spec.source, place("coeffs"), f"belief atom '{atom}': coeffs has "
                             f"{counted(len(coeffs), 'entry', 'entries')}, expected one per trust level of "
                             "the driver model (at least 2)",
                             f"give one coefficient per trust level, e.g. {N_TRUST_LEVELS} for the default "
                             "model")
        atoms[atom] = BeliefAtom(tuple(float(c) for c in coeffs), float(values["offset"]))
    return dict(sorted(atoms.items()))


def _inline_atoms(raw: Mapping[str, object], table: str, noun: str, fields: FieldTable[AtomValues],
                  example: str, spec: _SpecSource, taken: set[str]) -> Iterator[tuple[str, AtomValues, str]]:
    """The atom tables of inline tables (`[trust_states]`, `[type_beliefs]`): names unique across
    every atom table, each entry checked against `fields`. Yields (atom, values, place) in the
    file's order, as `[states]` is checked; `place` is the atom's line."""
    for atom in raw:
        spec.check_atom_name(atom, table)
        place = spec.place(f"{table}.{atom}", rf"^\s*\[{table}", rf"^\s*{re.escape(atom)}\s*=")
        if atom in taken:
            raise InputError(spec.source, place, f"atom '{atom}' is defined twice (also under another atom "
                             "table)", "rename one of them")
        entry = raw[atom]
        if not isinstance(entry, dict):
            raise InputError(spec.source, place, f"{noun} atom '{atom}' must be a table", example)

        def atom_place(key: str, place: str = place) -> str:
            return place

        values = check_fields(entry, fields, spec.source, f"{noun} atom '{atom}'", atom_place, owner=atom)
        yield atom, values, place


def _trust_state_atoms(raw: Mapping[str, object], spec: _SpecSource, town: Town | None,
                       taken: set[str]) -> dict[str, TrustStateAtom]:
    """The `[trust_states]` table: NAME = { roads = [...] (optional), trust = [levels] }."""
    atoms: dict[str, TrustStateAtom] = {}
    for atom, values, place in _inline_atoms(raw, "trust_states", "trust-state", TRUST_STATE_FIELDS,
                                             TRUST_STATE_EXAMPLE, spec, taken):
        roads = values["roads"]
        if roads is not None:

            def atom_place(road: str, place: str = place) -> str:
                return place

            _check_roads(roads, f"trust-state atom '{atom}'", atom_place, spec.source, town)
        atoms[atom] = TrustStateAtom(trust=frozenset(values["trust"]),
                                     roads=None if roads is None else frozenset(roads))
    return dict(sorted(atoms.items()))


def _type_belief_atoms(raw: Mapping[str, object], spec: _SpecSource,
                       taken: set[str]) -> dict[str, TypeBeliefAtom]:
    """The `[type_beliefs]` table: NAME = { types = ["flat", ...], above = 0.7 }."""
    atoms = {atom: TypeBeliefAtom(types=tuple(values["types"]), above=float(values["above"]))
             for atom, values, _ in _inline_atoms(raw, "type_beliefs", "type-belief", TYPE_BELIEF_FIELDS,
                                                  TYPE_BELIEF_EXAMPLE, spec, taken)}
    return dict(sorted(atoms.items()))


def _formula(formula_text: str, atoms: set[str], spec: _SpecSource) -> Formula:
    line, column = _formula_position(spec.text)
    try:
        return parse_formula(formula_text, atoms, spec.source, line, column)
    except RecursionError:
        raise spec.error("formula", (r"^\s*formula\s*=",), "the formula is nested too deeply to parse",
                         "simplify the formula") from None


def _check_start(start: str, spec: _SpecSource, town: Town | None) -> None:
    needles = (r"^\s*start\s*=",)
    if town is not None and start not in town.states:
        raise spec.error("start", needles, f"start road '{start}' is not a directed road of the "
                         f"town ({town.source_path or 'given town'})",
                         unknown_spec_road_fix(town, start))
    if "-" not in start:
        raise spec.error("start", needles, f"start '{start}' is not a directed road \"U-V\"",
                         'write start = "E-A"')


def spec_from_text(text: str, source: str = "<spec>", town: Town | None = None) -> Spec:
    """Parse and validate a spec's TOML text; with `town`, check its roads exist there."""
    spec = _SpecSource(text, source)
    values = check_fields(parse_toml(text, source, "spec file"), FIELDS, source, "spec file", spec.key_place)
    name, start, formula_text = values["name"], values["start"], values["formula"]
    _check_name(name, spec)
    _check_formula_size(formula_text, spec)
    count = len(values["states"]) + len(values["beliefs"])
    if count > MAX_ATOMS:
        raise InputError(source, "states", f"{count} atoms (the limit is {MAX_ATOMS})", "define fewer atoms")
    state_atoms = _state_atoms(values["states"], spec, town)
    belief_atoms = _belief_atoms(values["beliefs"], spec, set(state_atoms))
    trust_atoms = _trust_state_atoms(values["trust_states"], spec, town, set(state_atoms) | set(belief_atoms))
    type_atoms = _type_belief_atoms(values["type_beliefs"], spec,
                                    set(state_atoms) | set(belief_atoms) | set(trust_atoms))
    every_atom = set(state_atoms) | set(belief_atoms) | set(trust_atoms) | set(type_atoms)
    formula = _formula(formula_text, every_atom, spec)
    _check_start(start, spec, town)
    return Spec(name=name, start=start, formula_text=formula_text, formula=formula,
                state_atoms=state_atoms, belief_atoms=belief_atoms, source_path=source,
                trust_atoms=trust_atoms, type_atoms=type_atoms)


def check_coefficient_length(spec: Spec, n_trust: int, driver_source: str = "",
                             text: str | None = None) -> None:
    """InputError (one line, exit 2) when a belief atom's coeffs do not have one entry per trust level;
    given the spec's `text`, it names the line and column of the coeffs, as the loader's errors do."""
    source = spec.source_path or spec.name
    for name, atom in spec.belief_atoms.items():
        if len(atom.coeffs) != n_trust:
            raise InputError(source, f"beliefs.{name}.coeffs" if text is None
                             else _SpecSource(text, source).belief_place(name, "coeffs"),
                             f"belief atom '{name}' has {len(atom.coeffs)} coefficients but the driver "
                             f"model{f' ({driver_source})' if driver_source else ''} defines {n_trust} "
                             "trust levels",
                             f"give exactly {n_trust} coefficients, one per trust level")


def load_spec(path: str | Path, town: Town | None = None, n_trust: int | None = None,
              driver_source: str = "") -> Spec:
    """Load and validate a spec file or a packaged spec by name (trustroute/core/packaged.py), through
    the guarded reader (trustroute/core/validation.py); with `town`, also check its roads against the
    town; with `n_trust`, the trust levels of the driver model (or population, named by
    `driver_source`) it is used with, check every belief atom has one coefficient per level. Every
    command that reads a spec with a driver model loads it here."""
    path = SPECS.resolve(path)   # a file, or a packaged spec by name ("phi1")
    text = read_text(path, str(path), "the spec file", SPECS.fix())
    spec = spec_from_text(text, str(path), town)
    if n_trust is not None:
        check_coefficient_length(spec, n_trust, driver_source, text)
    return spec


def state_only_projection(spec: Spec) -> Spec:
    """The spec with every belief and type-belief literal (positive or negated) replaced by true,
    and every
    trust-state literal by its most permissive reading on the road alone: a positive literal by
    its roads (true when it has none), a negated one by true unless it names every trust level
    (then by the negation of its roads). The projection holds wherever some trust and some
    belief make the spec's literal hold, so a route satisfying the spec satisfies it."""
    state_atoms = dict(spec.state_atoms)

    def replace(literal: Literal) -> Formula:
        if literal.atom in spec.belief_atoms or literal.atom in spec.type_atoms:
            return TRUE
        trust = spec.trust_atoms.get(literal.atom)
        if trust is None:
            return literal
        every_level = len(trust.trust) == N_TRUST_LEVELS
        if literal.positive or every_level:
            if trust.roads is None:
                return TRUE if literal.positive else FALSE
            state_atoms[literal.atom] = trust.roads
            return literal
        return TRUE

    formula = map_literals(spec.formula, replace)
    return Spec(name=f"{spec.name} (state-only)", start=spec.start, formula_text=format_formula(formula),
                formula=formula, state_atoms=state_atoms, belief_atoms={},
                source_path=spec.source_path)
