"""Warnings about scLDTL specs that parse but do not mean what their author likely intended.

Checks (each warning has a stable `code`):
- `belief-never-true` / `belief-always-true`: g(b) = offset - coeffs.b is linear, so its extremes
  over the probability simplex are at the vertices: the atom is never true iff max(coeffs) <= offset,
  always true iff min(coeffs) > offset.
- `atom-no-effect`: an atom of the formula that no reachable state of the minimal DFA tests
  (its value never changes the successor), e.g. `a` in `a U (F b)`, which is `F b`.
- `subformula-no-effect`: a compound subformula whose replacement by true and by false both leave
  the DFA's language unchanged (negation only on atoms, so the formula is monotone in it: then no
  value matters), e.g. `b & c` in `(b & c) U (F b)`. Not repeated for subformulas whose atoms
  are all reported by `atom-no-effect`, nor inside a reported subformula.
- `unused-atom`: defined in the file but not used by the formula.
- `unsatisfiable`: the DFA's initial state cannot reach acceptance.
- `precedence`: '&' or '|' and 'U' side by side in one parenthesised group, e.g. `a & b U c`. The
  parser reads U tighter than & and | (`a & (b U c)`; policies/logic/formula.py); the warning
  states that reading and asks for parentheses.
With a town (and a driver model: the packaged one unless given):
- `threshold-hit`: a belief atom's threshold lies within the rounding margin
  (labelling.Labeller.belief_margins) of c·b for a belief the vehicle really reaches: the prior,
  or the posterior after up to THRESHOLD_DEPTH observations (e.g. a multiple of 1/n under a
  uniform prior, which no `none` road moves). Synthesis then treats the label as either value,
  which widens [L, U]; moving the offset off the hit avoids that.
- `rejected-at-start`: the DFA rejects at position 0 (the start road read with the prior belief,
  e.g. `(!lowtrust) U ...` whose lowtrust holds at the prior): every policy is worth 0.
- `state-unreachable`: a state atom none of whose roads can be reached from the start.
- `town-unsatisfiable`: no route satisfies even the state-only projection (every belief literal
  true): no accepting (road, q) is reachable in the town × projected-DFA product.
Type-belief atoms (docs/driver_types.md): lint a spec with them against a driver population
(`trustroute spec check SPEC --population FILE`: the spec lifted to the population's type-aware
model, so a type it does not have is an error and the threshold check reads the joint filter);
without one:
- `type-belief-unchecked`: the atom's types are not checked (no population given).
Trust-state atoms (docs/trust_states.md):
- `trust-every-level`: the atom names every trust level, so it tests the road only (a state atom).
- `trust-unreachable` (with a town): none of the atom's roads can be reached from the start.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel, load_driver_model
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.dfa import DFA, Cube, build_dfa, dfa_from_formula
from trustroute.policies.logic.formula import (
    FALSE,
    TRUE,
    And,
    Const,
    Eventually,
    Formula,
    Literal,
    Next,
    Or,
    Until,
    atoms_in_order,
    format_formula,
    walk,
)
from trustroute.policies.logic.spec import N_TRUST_LEVELS, Spec, state_only_projection
from trustroute.policies.model.trust_pomdp import build_pomdp

THRESHOLD_DEPTH = 3


@dataclass(frozen=True)
class LintWarning:
    code: str
    message: str
    atom: str = ""


def belief_warnings(spec: Spec) -> list[LintWarning]:
    warnings = []
    for name, atom in spec.belief_atoms.items():
        high, low = max(atom.coeffs), min(atom.coeffs)
        if high <= atom.offset:
            warnings.append(LintWarning(
                "belief-never-true", f"belief atom '{name}' is never true on the probability simplex: "
                f"coeffs.b <= max(coeffs) = {high:g} <= offset {atom.offset:g}", name))
        elif low > atom.offset:
            warnings.append(LintWarning(
                "belief-always-true", f"belief atom '{name}' is always true on the probability simplex: "
                f"coeffs.b >= min(coeffs) = {low:g} > offset {atom.offset:g}", name))
    return warnings


def no_effect_warnings(spec: Spec, dfa: DFA) -> list[LintWarning]:
    tested: set[str] = set()
    for q in range(dfa.n_states):
        tested.update(dfa.tested_atoms(q))
    warnings = []
    for atom in dfa.atoms:
        if atom in tested:
            continue
        uses = sorted({format_formula(n) for n in walk(spec.formula)
                       if isinstance(n, Literal) and n.atom == atom})
        warnings.append(LintWarning(
            "atom-no-effect", f"atom '{atom}' cannot affect satisfaction: no state of the minimal DFA "
            f"tests it, so {' and '.join(uses)} in the formula constrains nothing "
            "(as in a U (F b), which is F b)", atom))
    return warnings


MAX_STATES_FOR_SUBFORMULA_CHECK = 300


def equivalent(first: DFA, second: DFA) -> bool:
    """Language equivalence of two DFAs over possibly different atoms: breadth-first search over
    pairs of states, a pair's successors read off consistent pairs of guard cubes."""
    seen = {(first.initial, second.initial)}
    stack = [(first.initial, second.initial)]
    while stack:
        p, q = stack.pop()
        if first.accepting[p] != second.accepting[q]:
            return False
        for p2, cubes1 in first.transitions(p).items():
            for q2, cubes2 in second.transitions(q).items():
                if (p2, q2) in seen:
                    continue
                if any(_consistent(c1, c2) for c1 in cubes1 for c2 in cubes2):
                    seen.add((p2, q2))
                    stack.append((p2, q2))
    return True


def _consistent(first: Cube, second: Cube) -> bool:
    values = dict(first)
    return all(values.get(atom, value) == value for atom, value in second)


def _replace_at(formula: Formula, target: int, replacement: Formula) -> tuple[Formula, int]:
    """`formula` with its pre-order node number `target` replaced; returns (new formula, nodes seen)."""
    if target == 0:
        return replacement, sum(1 for _ in walk(formula))
    seen = 1
    if isinstance(formula, And | Or):
        parts = []
        for part in formula.parts:
            new, count = _replace_at(part, target - seen, replacement)
            parts.append(new)
            seen += count
        return type(formula)(tuple(parts)), seen
    if isinstance(formula, Next | Eventually):
        body, count = _replace_at(formula.body, target - 1, replacement)
        return type(formula)(body), count + 1
    if isinstance(formula, Until):
        left, count_left = _replace_at(formula.left, target - 1, replacement)
        right, count_right = _replace_at(formula.right, target - 1 - count_left, replacement)
        return Until(left, right), 1 + count_left + count_right
    return formula, 1


def subformula_warnings(spec: Spec, dfa: DFA, atoms_without_effect: set[str]) -> list[LintWarning]:
    if dfa.n_states > MAX_STATES_FOR_SUBFORMULA_CHECK:
        return []  # each candidate costs two translations: keep the linter fast on huge specs
    nodes = list(walk(spec.formula))
    warnings: list[LintWarning] = []
    reported_until = -1   # pre-order: the nodes inside a reported subformula come right after it
    for index, node in enumerate(nodes):
        if index == 0 or index < reported_until or isinstance(node, Const | Literal):
            continue
        if set(atoms_in_order(node)) <= atoms_without_effect:
            continue
        variants = (_replace_at(spec.formula, index, value)[0] for value in (TRUE, FALSE))
        if all(equivalent(dfa, dfa_from_formula(v, dfa.atoms)) for v in variants):
            warnings.append(LintWarning(
                "subformula-no-effect", f"subformula '{format_formula(node)}' cannot affect satisfaction: "
                "the spec means the same with it replaced by true or by false"))
            reported_until = index + sum(1 for _ in walk(node))
    return warnings


def unused_warnings(spec: Spec) -> list[LintWarning]:
    used = set(spec.formula_atoms)
    return [LintWarning("unused-atom", f"atom '{atom}' is defined but the formula does not use it", atom)
            for atom in spec.atoms if atom not in used]


def unreachable_warnings(spec: Spec, town: Town) -> list[LintWarning]:
    reachable = town.reachable_states(spec.start)
    used = set(spec.formula_atoms)
    return [LintWarning("state-unreachable", f"state atom '{atom}': none of its roads can be reached "
                        f"from the start {spec.start}", atom)
            for atom, roads in spec.state_atoms.items() if atom in used and not roads & reachable]


def town_satisfiable(spec: Spec, town: Town) -> bool:
    """True iff some route from the start satisfies the state-only projection of `spec`."""
    projected = state_only_projection(spec)
    compiled = compile_spec(projected, town)
    dfa, labeller = compiled.dfa, compiled.labeller
    n_roads = len(town.states)
    beliefs = np.full((1, 7), 1.0 / 7.0)  # no belief atoms remain: any belief labels the same
    q0 = int(labeller.step(np.array([dfa.initial]), np.array([town.state_index(spec.start)]), beliefs)[0])
    next_state = labeller.step(
        np.repeat(np.arange(dfa.n_states), n_roads), np.tile(np.arange(n_roads), dfa.n_states),
        np.broadcast_to(beliefs, (dfa.n_states * n_roads, 7))).reshape(dfa.n_states, n_roads)
    successors = [[town.state_index(s) for s in town.successors(r)] for r in town.states]
    start = (town.state_index(spec.start), q0)
    seen = {start}
    stack = [start]
    while stack:
        x, q = stack.pop()
        if dfa.accepting[q]:
            return True
        for x2 in successors[x]:
            nxt = (x2, int(next_state[q, x2]))
            if nxt not in seen:
                seen.add(nxt)
                stack.append(nxt)
    return False


def trust_warnings(spec: Spec, town: Town | None = None) -> list[LintWarning]:
    warnings = []
    used = set(spec.formula_atoms)
    reachable = town.reachable_states(spec.start) if town is not None else None
    for name, atom in sorted(spec.trust_atoms.items()):
        if len(atom.trust) == N_TRUST_LEVELS:
            warnings.append(LintWarning(
                "trust-every-level", f"trust-state atom '{name}' names every trust level: it tests the "
                "road only (write it under [states])", name))
        if reachable is not None and atom.roads is not None and name in used and not atom.roads & reachable:
            warnings.append(LintWarning(
                "trust-unreachable", f"trust-state atom '{name}': none of its roads can be reached from "
                f"the start {spec.start}", name))
    return warnings


def precedence_warnings(spec: Spec) -> list[LintWarning]:
    """'&'/'|' mixed with 'U' at one parenthesis depth of the formula text."""
    operators: list[set[str]] = [set()]
    mixed = False
    for token in re.findall(r"[()&|]|\bU\b", spec.formula_text):
        if token == "(":
            operators.append(set())
        elif token == ")":
            group = operators.pop() if len(operators) > 1 else operators[0]
            mixed |= "U" in group and bool(group & {"&", "|"})
        else:
            operators[-1].add(token)
    mixed |= any("U" in group and bool(group & {"&", "|"}) for group in operators)
    if not mixed:
        return []
    return [LintWarning(
        "precedence", f"formula '{spec.formula_text}' mixes '&' or '|' with 'U' without parentheses; "
        "it is read with U binding tighter than & and | (a & b U c is a & (b U c)), as "
        f"'{format_formula(spec.formula)}': add parentheses to say which you mean")]


def threshold_warnings(spec: Spec, town: Town, driver: DriverModel) -> list[LintWarning]:
    """Belief atoms whose threshold a reachable belief hits within the rounding margin."""
    if (not spec.belief_atoms or spec.type_atoms
            or any(len(a.coeffs) != driver.n_trust for a in spec.belief_atoms.values())):
        return []

    pomdp = build_pomdp(town, driver)
    compiled = compile_spec(spec, town)
    dfa, labeller = compiled.dfa, compiled.labeller
    symbols = [(i, h, e) for i in range(len(driver.incident_types)) for h in (0, 1)
               for e in ((0, 1) if driver.depends_on_performance else (0,))]
    layer = np.asarray(driver.initial_belief, dtype=float)[None, :]
    reached = [layer]
    for _ in range(THRESHOLD_DEPTH):
        grown = []
        for i, h, e in symbols:
            posterior, probability = pomdp.belief_update(layer, i, h, e)
            grown.append(posterior[probability > 0])
        layer = np.unique(np.concatenate(grown), axis=0)
        reached.append(layer)
    beliefs = np.concatenate(reached)
    _, either = labeller.belief_margins(beliefs)
    names = [dfa.atoms[c] for c in labeller.belief_columns]
    warnings = []
    for j, name in enumerate(names):
        hits = np.flatnonzero(either[:, j])
        if hits.size == 0:
            continue
        atom = spec.belief_atoms[name]
        value = float(beliefs[hits[0]] @ np.asarray(atom.coeffs))
        warnings.append(LintWarning(
            "threshold-hit", f"belief atom '{name}': the threshold {atom.offset!r} is hit exactly (within "
            f"rounding) by c·b = {value!r} at {hits.size} belief(s) the vehicle reaches within "
            f"{THRESHOLD_DEPTH} observations (e.g. the prior or after 'none' roads); the label there "
            "depends on rounding, so synthesis counts it as either value: move the offset off the hit", name))
    return warnings


def start_warnings(spec: Spec, town: Town, driver: DriverModel) -> list[LintWarning]:
    """The DFA rejects at position 0: the start road with the driver model's prior belief (not
    decided for trust-state atoms, whose position 0 reads the hidden trust)."""
    if (spec.trust_atoms or spec.type_atoms
            or any(len(a.coeffs) != driver.n_trust for a in spec.belief_atoms.values())):
        return []
    compiled = compile_spec(spec, town)
    prior = np.asarray(driver.initial_belief, dtype=float)
    if not compiled.rejecting[compiled.initial_state(prior)]:
        return []
    held = [f"{name} (c·b = {float(prior @ np.asarray(atom.coeffs)):.4g} > {atom.offset!r})"
            for name, atom in sorted(spec.belief_atoms.items())
            if name in compiled.dfa.atoms and float(prior @ np.asarray(atom.coeffs)) > atom.offset]
    return [LintWarning(
        "rejected-at-start", f"the spec is rejected at position 0, the start road {spec.start} read with "
        "the prior belief, so every policy is worth 0"
        + (f": {', '.join(held)} already holds there" if held else ""))]


def lint(spec: Spec, town: Town | None = None, dfa: DFA | None = None,
         driver: DriverModel | None = None) -> list[LintWarning]:
    """Every warning that applies to `spec` (and to `town` when given, with `driver` or the
    packaged driver model for the threshold check)."""
    dfa = dfa if dfa is not None else build_dfa(spec)
    no_effect = no_effect_warnings(spec, dfa)
    warnings = (belief_warnings(spec) + no_effect
                + subformula_warnings(spec, dfa, {w.atom for w in no_effect}) + unused_warnings(spec)
                + trust_warnings(spec, town)
                + precedence_warnings(spec))
    for name in sorted(spec.type_atoms):
        warnings.append(LintWarning(
            "type-belief-unchecked", f"type-belief atom '{name}' names driver types "
            f"{list(spec.type_atoms[name].types)}; check them against a driver population with "
            "--population FILE", name))
    if dfa.rejecting[dfa.initial]:
        warnings.append(LintWarning("unsatisfiable", "no trace satisfies the formula (the DFA's "
                                    "initial state cannot reach acceptance)"))
    elif town is not None:
        driver = driver if driver is not None else load_driver_model()
        warnings += start_warnings(spec, town, driver) + unreachable_warnings(spec, town)
        if not town_satisfiable(spec, town):
            warnings.append(LintWarning(
                "town-unsatisfiable", f"no route from {spec.start} satisfies the spec on this town, "
                "even with every belief atom true"))
        warnings += threshold_warnings(spec, town, driver)
    return warnings
