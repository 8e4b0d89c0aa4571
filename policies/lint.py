"""Warnings about scLDTL specs that parse but do not mean what their author likely intended.

Checks (each warning has a stable `code`):
- `belief-never-true` / `belief-always-true`: g(b) = offset - coeffs.b is linear, so its extremes
  over the probability simplex are at the vertices: the atom is never true iff max(coeffs) <= offset,
  always true iff min(coeffs) > offset.
- `atom-no-effect`: an atom of the formula that no reachable state of the minimal DFA tests
  (its value never changes the successor), e.g. `a` in `a U (F b)`, which is `F b`.
- `unused-atom`: defined in the file but not used by the formula.
- `unsatisfiable`: the DFA's initial state cannot reach acceptance.
With a town:
- `state-unreachable`: a state atom none of whose roads can be reached from the start.
- `town-unsatisfiable`: no route satisfies even the state-only projection (every belief literal
  true): no accepting (road, q) is reachable in the town × projected-DFA product.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from networks.town import Town
from policies.dfa import DFA, build_dfa
from policies.labelling import Labeller
from policies.spec import Spec, state_only_projection


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
    return [LintWarning("atom-no-effect", f"atom '{atom}' cannot affect satisfaction: no state of the "
                        f"minimal DFA tests it (the subformulas using it are redundant)", atom)
            for atom in dfa.atoms if atom not in tested]


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
    dfa = build_dfa(projected)
    labeller = Labeller(projected, dfa, town)
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


def lint(spec: Spec, town: Town | None = None, dfa: DFA | None = None) -> list[LintWarning]:
    """Every warning that applies to `spec` (and to `town` when given)."""
    dfa = dfa if dfa is not None else build_dfa(spec)
    warnings = belief_warnings(spec) + no_effect_warnings(spec, dfa) + unused_warnings(spec)
    if dfa.rejecting[dfa.initial]:
        warnings.append(LintWarning("unsatisfiable", "no trace satisfies the formula (the DFA's "
                                    "initial state cannot reach acceptance)"))
    elif town is not None:
        warnings += unreachable_warnings(spec, town)
        if not town_satisfiable(spec, town):
            warnings.append(LintWarning(
                "town-unsatisfiable", f"no route from {spec.start} satisfies the spec on this town, "
                "even with every belief atom true"))
    return warnings
