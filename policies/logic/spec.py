"""scLDTL spec files: TOML schema, validation (optionally against a town), identity, projection.

A spec file (e.g. specs/phi1.toml) has `name`, `start` (directed road "U-V", position 0),
`formula` (policies/logic/formula.py grammar), a `[states]` table (atom -> list of directed roads) and
`[beliefs.NAME]` tables with `coeffs` (one per trust level of the driver model; the default model
has 7, and the labeller checks the length against the model in use) and `offset`: a belief atom is true
iff `offset - coeffs·b < 0` (strict; docs/model.md, "scLDTL"; every key: docs/formats/spec.md), and a
`[trust_states]` table of
trust-state atoms `NAME = { roads = [...], trust = [6, 7] }`: true at a position iff the road is
one of `roads` (any road when `roads` is absent) and the human's hidden trust is one of the levels
`trust` (docs/trust_states.md), and a `[type_beliefs]` table of type-belief atoms
`NAME = { types = ["flat"], above = 0.7 }`: true iff the AV's belief that the driver is of one of
`types` exceeds `above` (strict; the types of a driver population, docs/driver_types.md). Every
error is an InputError naming the file, line and column.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.core.validation import parse_toml, read_text, require_keys
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

N_TRUST_LEVELS = 7  # the Muir scale 1..7 of the default driver model (any number >= 2 is accepted)
TOP_LEVEL_KEYS = ("name", "start", "formula", "states", "beliefs", "trust_states", "type_beliefs")
MAX_SPEC_NAME = 64
# Names become file names (policy cache entries): no path separators, NUL or leading dot.
SPEC_NAME = re.compile(rf"[A-Za-z0-9_][A-Za-z0-9_.+-]{{0,{MAX_SPEC_NAME - 1}}}")
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

def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _paren_depth(text: str) -> int:
    depth = deepest = 0
    for char in text:
        if char == "(":
            depth += 1
            deepest = max(deepest, depth)
        elif char == ")":
            depth -= 1
    return deepest


def spec_from_text(text: str, source: str = "<spec>", town: Town | None = None) -> Spec:
    """Parse and validate a spec's TOML text; with `town`, check its roads exist there."""
    data = parse_toml(text, source, "spec file")

    def fail(label: str, needles: tuple[str, ...], problem: str, fix: str) -> InputError:
        return InputError(source, _place(text, label, *needles), problem, fix)

    for key in data:
        if key not in TOP_LEVEL_KEYS:
            raise fail(key, (rf"^\s*\[?{re.escape(key)}\b",), f"unknown key '{key}'",
                       f"use only {', '.join(TOP_LEVEL_KEYS)}")
    require_keys(data, ("name", "start", "formula"), source,
                 lambda key: f"add {key} = \"...\" at the top of the file (see specs/phi1.toml)")
    for key in ("name", "start", "formula"):
        if not isinstance(data[key], str):
            raise fail(key, (rf"^\s*{key}\s*=",), f"'{key}' must be a string", f'write {key} = "..."')
    name, start, formula_text = data["name"], data["start"], data["formula"]
    if not name.strip():
        raise fail("name", (r"^\s*name\s*=",), "'name' is empty", 'write name = "phi1"')
    if not SPEC_NAME.fullmatch(name):
        raise fail("name", (r"^\s*name\s*=",), f"spec name {name[:40]!r}{'...' if len(name) > 40 else ''} "
                   f"is not 1-{MAX_SPEC_NAME} letters, digits, '_', '.' or '-' (it names cache files)",
                   'write e.g. name = "phi1"')
    if len(formula_text) > MAX_FORMULA_CHARS:
        raise fail("formula", (r"^\s*formula\s*=",), f"the formula has {len(formula_text)} characters "
                   f"(the limit is {MAX_FORMULA_CHARS})", "split the task or simplify the formula")
    nesting = _paren_depth(formula_text)
    if nesting > MAX_FORMULA_NESTING:
        raise fail("formula", (r"^\s*formula\s*=",), f"the formula nests parentheses {nesting} deep "
                   f"(the limit is {MAX_FORMULA_NESTING})", "simplify the formula")

    raw_states = data.get("states", {})
    raw_beliefs = data.get("beliefs", {})
    if not isinstance(raw_states, dict):
        raise fail("states", (r"^\s*states\s*=",), "'states' must be a table of atom -> roads",
                   'write [states] then v1 = ["B-G", "F-G"]')
    if not isinstance(raw_beliefs, dict):
        raise fail("beliefs", (r"^\s*beliefs\s*=",), "'beliefs' must be a table of tables",
                   "write [beliefs.NAME] with coeffs = [...] and offset = ...")

    if len(raw_states) + len(raw_beliefs) > MAX_ATOMS:
        raise InputError(source, "states", f"{len(raw_states) + len(raw_beliefs)} atoms (the limit is "
                         f"{MAX_ATOMS})", "define fewer atoms")

    def check_atom_name(atom: str, table: str) -> None:
        if not ATOM_PATTERN.fullmatch(atom) or atom in KEYWORDS:
            raise fail(f"{table}.{atom}", (re.escape(atom),), f"'{atom}' is not a valid atom name",
                       "use letters, digits and '_' (not starting with a digit), and not "
                       + ", ".join(sorted(KEYWORDS)))

    state_atoms: dict[str, frozenset[str]] = {}
    for atom in sorted(raw_states):
        roads = raw_states[atom]
        check_atom_name(atom, "states")
        label = f"states.{atom}"
        needles = (r"^\s*\[states\]", rf"^\s*{re.escape(atom)}\s*=")
        if not (isinstance(roads, list) and len(roads) <= MAX_STATE_ROADS
                and all(isinstance(r, str) for r in roads)):
            raise fail(label, needles, f"state atom '{atom}' must be a list of directed roads",
                       f'write {atom} = ["U-V", ...]')
        for road in roads:
            if "-" not in road:
                raise fail(label, needles + (re.escape(f'"{road}"'),),
                           f"'{road}' is not a directed road \"U-V\"", "write roads as \"U-V\"")
            if town is not None and road not in town.states:
                raise fail(label, needles + (re.escape(f'"{road}"'),),
                           f"state atom '{atom}': '{road}' is not a directed road of the town "
                           f"({town.source_path or 'given town'})",
                           "use directed roads 'U-V' of the town (trustroute model lists them)")
        state_atoms[atom] = frozenset(roads)

    belief_atoms: dict[str, BeliefAtom] = {}
    for atom in sorted(raw_beliefs):
        table = raw_beliefs[atom]
        check_atom_name(atom, "beliefs")
        label = f"beliefs.{atom}"
        header = (rf"^\s*\[beliefs\.{re.escape(atom)}\]",)
        if atom in state_atoms:
            raise fail(label, header, f"atom '{atom}' is defined both under [states] and [beliefs]",
                       "rename one of them")
        if not isinstance(table, dict):
            raise fail(label, header, f"belief atom '{atom}' must be a table",
                       f"write [beliefs.{atom}] with coeffs = [...] and offset = ...")
        for key in table:
            if key not in ("coeffs", "offset"):
                raise fail(label, header + (rf"^\s*{re.escape(key)}\s*=",),
                           f"unknown key '{key}' in belief atom '{atom}'", "use only coeffs and offset")
        for key in ("coeffs", "offset"):
            if key not in table:
                raise fail(label, header, f"belief atom '{atom}' is missing '{key}'",
                           f"add {key} = ... under [beliefs.{atom}]")
        coeffs, offset = table["coeffs"], table["offset"]
        coeffs_place = header + (r"^\s*coeffs\s*=",)
        if not (isinstance(coeffs, list) and all(_number(c) for c in coeffs)):
            raise fail(label, coeffs_place, f"belief atom '{atom}': coeffs must be a list of finite "
                       "numbers", "write coeffs = [1, 0, 0, 0, 0, 0, 0]")
        if len(coeffs) < 2:
            raise fail(label, coeffs_place, f"belief atom '{atom}': coeffs has {len(coeffs)} entries, "
                       "expected one per trust level of the driver model (at least 2)",
                       f"give one coefficient per trust level, e.g. {N_TRUST_LEVELS} for the default model")
        if not _number(offset):
            raise fail(label, header + (r"^\s*offset\s*=",), f"belief atom '{atom}': offset must be "
                       "a finite number", "write offset = 0.5")
        belief_atoms[atom] = BeliefAtom(tuple(float(c) for c in coeffs), float(offset))

    trust_atoms = _trust_state_atoms(data.get("trust_states", {}), text, source, town,
                                     set(state_atoms) | set(belief_atoms), check_atom_name)
    type_atoms = _type_belief_atoms(data.get("type_beliefs", {}), text, source,
                                    set(state_atoms) | set(belief_atoms) | set(trust_atoms),
                                    check_atom_name)
    line, column = _formula_position(text)
    try:
        formula = parse_formula(formula_text, set(state_atoms) | set(belief_atoms) | set(trust_atoms)
                                | set(type_atoms), source, line, column)
    except RecursionError:
        raise fail("formula", (r"^\s*formula\s*=",), "the formula is nested too deeply to parse",
                   "simplify the formula") from None
    if town is not None and start not in town.states:
        raise fail("start", (r"^\s*start\s*=",), f"start road '{start}' is not a directed road of the "
                   f"town ({town.source_path or 'given town'})", "use a directed road 'U-V' of the town")
    if "-" not in start:
        raise fail("start", (r"^\s*start\s*=",), f"start '{start}' is not a directed road \"U-V\"",
                   'write start = "E-A"')
    return Spec(name=name, start=start, formula_text=formula_text, formula=formula,
                state_atoms=state_atoms, belief_atoms=belief_atoms, source_path=source,
                trust_atoms=trust_atoms, type_atoms=type_atoms)


def _atom_entries(raw: object, table: str, noun: str, keys: tuple[str, ...], required: tuple[str, ...],
                  example: str, text: str, source: str, taken: set[str], check_atom_name):
    """The checks every atom table shares (`[type_beliefs]`, `[trust_states]`): a table of atom ->
    inline table, names unique across kinds, only `keys`, every key of `required` present. Yields
    (atom, entry, fail) in name order; `fail(problem, fix)` places an error at the atom's line."""
    if not isinstance(raw, dict):
        raise InputError(source, _place(text, table, rf"^\s*{table}\s*="),
                         f"'{table}' must be a table of atom -> {{ {', '.join(keys)} }}", example)
    for atom in sorted(raw):
        entry = raw[atom]
        check_atom_name(atom, table)
        place = _place(text, f"{table}.{atom}", rf"^\s*\[{table}", rf"^\s*{re.escape(atom)}\s*=")

        def fail(problem: str, fix: str, place: str = place) -> InputError:
            return InputError(source, place, problem, fix)

        if atom in taken:
            raise fail(f"atom '{atom}' is defined twice (also under another atom table)",
                       "rename one of them")
        if not isinstance(entry, dict):
            raise fail(f"{noun} atom '{atom}' must be a table", example)
        for key in entry:
            if key not in keys:
                raise fail(f"unknown key '{key}' in {noun} atom '{atom}'",
                           f"use only {' and '.join(keys)}")
        for key in required:
            if key not in entry:
                raise fail(f"{noun} atom '{atom}' is missing '{key}'", example)
        yield atom, entry, fail


def _type_belief_atoms(raw: object, text: str, source: str, taken: set[str],
                       check_atom_name) -> dict[str, TypeBeliefAtom]:
    """The `[type_beliefs]` table: NAME = { types = ["flat", ...], above = 0.7 }."""
    example = 'write [type_beliefs] then nontruster = { types = ["flat"], above = 0.7 }'
    atoms: dict[str, TypeBeliefAtom] = {}
    for atom, entry, fail in _atom_entries(raw, "type_beliefs", "type-belief", ("types", "above"),
                                           ("types", "above"), example, text, source, taken,
                                           check_atom_name):
        types = entry["types"]
        if not (isinstance(types, list) and types and all(isinstance(t, str) and t for t in types)
                and len(set(types)) == len(types)):
            raise fail(f"type-belief atom '{atom}': types must be a non-empty list of distinct type names",
                       'write types = ["flat"]')
        above = entry["above"]
        if not (_number(above) and 0 <= above < 1):
            raise fail(f"type-belief atom '{atom}': above must be a number in [0, 1)",
                       "write above = 0.7 (the atom is true iff P(type in types) > above)")
        atoms[atom] = TypeBeliefAtom(types=tuple(types), above=float(above))
    return atoms


def _trust_state_atoms(raw: object, text: str, source: str, town: Town | None, taken: set[str],
                       check_atom_name) -> dict[str, TrustStateAtom]:
    """The `[trust_states]` table: NAME = { roads = [...] (optional), trust = [levels] }."""
    example = "write [trust_states] then trusting = { roads = [\"K-L\"], trust = [6, 7] }"
    atoms: dict[str, TrustStateAtom] = {}
    for atom, entry, fail in _atom_entries(raw, "trust_states", "trust-state", ("roads", "trust"),
                                           ("trust",), example, text, source, taken, check_atom_name):
        levels = entry["trust"]
        if not (isinstance(levels, list) and levels
                and all(isinstance(v, int) and not isinstance(v, bool) for v in levels)
                and all(1 <= v <= N_TRUST_LEVELS for v in levels)):
            raise fail(f"trust-state atom '{atom}': trust must be a non-empty list of "
                       f"trust levels (integers 1..{N_TRUST_LEVELS})", "write trust = [6, 7]")
        roads = entry.get("roads")
        if roads is not None:
            if not (isinstance(roads, list) and all(isinstance(r, str) for r in roads)):
                raise fail(f"trust-state atom '{atom}': roads must be a list of directed roads",
                           'write roads = ["U-V", ...] or leave it out for any road')
            for road in roads:
                if "-" not in road:
                    raise fail(f"'{road}' is not a directed road \"U-V\"", "write roads as \"U-V\"")
                if town is not None and road not in town.states:
                    raise fail(f"trust-state atom '{atom}': '{road}' is not a directed "
                               f"road of the town ({town.source_path or 'given town'})",
                               "use directed roads 'U-V' of the town (trustroute model lists them)")
        atoms[atom] = TrustStateAtom(trust=frozenset(levels),
                                     roads=None if roads is None else frozenset(roads))
    return atoms


def load_spec(path: str | Path, town: Town | None = None) -> Spec:
    """Load and validate a spec file (through the guarded reader, trustroute/core/validation.py); with
    `town`, also check its roads against the town."""
    text = read_text(path, str(path), "the spec file", "pass an existing .toml file, e.g. specs/phi1.toml")
    return spec_from_text(text, str(path), town)


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
