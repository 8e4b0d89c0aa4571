"""The complete minimal DFA of an scLDTL formula, with Boolean guards as decision diagrams.

Construction (no table over 2^atoms anywhere):
1. Formula progression: a DFA state is a canonical formula (the obligation still open before
   reading the next position). Progressing a state gives a formula over `Now` literals of the
   position being read; Shannon expansion on the atoms that actually occur there, in a fixed atom
   order, gives an ordered decision diagram whose leaves are the successor obligations.
2. Good prefixes: a state is accepting iff its obligation holds on every continuation (every
   path from it reaches the obligation `true`), so acceptance is at the first good prefix even
   for formulas such as `X a | X !a`; accepting states are absorbing.
3. Minimisation: Moore partition refinement, where a state's signature is its decision diagram
   with leaves replaced by blocks, reduced and hash-consed (canonical for the fixed atom order).

`step_many` walks the shared node table for many (state, valuation) pairs at once with numpy.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trustroute.core.errors import InputError
from trustroute.policies.logic.formula import (
    TRUE,
    And,
    Const,
    Eventually,
    Formula,
    Literal,
    Next,
    Now,
    Or,
    Until,
    atoms_in_order,
    canonical,
    disjunctive_normal_form,
    format_formula,
    make_and,
    make_or,
)
from trustroute.policies.logic.spec import Spec

Cube = tuple[tuple[str, bool], ...]  # a conjunction of literals (atom, value)
# LTL-to-DFA is doubly exponential in the worst case: stop exploring beyond these sizes.
MAX_STATES = 20_000
MAX_NODES = 1_000_000


class DFATooLarge(ValueError):
    """The progression automaton outgrew MAX_STATES or MAX_NODES."""


@dataclass(frozen=True, eq=False)
class DFA:
    """A complete minimal DFA. Guards live in one node table shared by all states:
    node_atom[k] is the atom index tested at node k (-1 at a leaf), node_low/node_high the
    children for false/true, node_target the successor state at a leaf; root[q] is state q's
    diagram. State 0 is the initial state."""

    atoms: tuple[str, ...]
    n_states: int
    initial: int
    accepting: np.ndarray
    rejecting: np.ndarray
    root: np.ndarray
    node_atom: np.ndarray
    node_low: np.ndarray
    node_high: np.ndarray
    node_target: np.ndarray
    state_formulas: tuple[str, ...]   # the obligation of each state (one representative)

    def step(self, q: int, valuation: Mapping[str, bool]) -> int:
        """Successor of state q on one valuation (atoms the guard tests must be present)."""
        node = int(self.root[q])
        while self.node_atom[node] >= 0:
            value = bool(valuation[self.atoms[int(self.node_atom[node])]])
            node = int(self.node_high[node] if value else self.node_low[node])
        return int(self.node_target[node])

    def step_many(self, q: np.ndarray, valuations: np.ndarray) -> np.ndarray:
        """Successors of states q (int [n]) on valuations (bool [n, len(atoms)])."""
        q = np.asarray(q, dtype=np.int64)
        values = np.asarray(valuations, dtype=bool)
        if q.shape == (1,):   # one position (an episode's road, say): a plain walk costs less
            one = int(self.root[q[0]])
            row = values[0]
            while (atom := self.node_atom[one]) >= 0:
                one = int(self.node_high[one] if row[atom] else self.node_low[one])
            return self.node_target[[one]]
        node = self.root[q]
        active = np.flatnonzero(self.node_atom[node] >= 0)
        while active.size:
            current = node[active]
            tested = self.node_atom[current]
            chosen = np.where(values[active, tested], self.node_high[current], self.node_low[current])
            node[active] = chosen
            active = active[self.node_atom[chosen] >= 0]
        return self.node_target[node]

    # -- guards -------------------------------------------------------------------------------
    def transitions(self, q: int) -> dict[int, list[Cube]]:
        """Successor -> guard of state q, the guard a disjunction of cubes (one per diagram path)."""
        result: dict[int, list[Cube]] = {}
        stack: list[tuple[int, Cube]] = [(int(self.root[q]), ())]
        while stack:
            node, cube = stack.pop()
            atom = int(self.node_atom[node])
            if atom < 0:
                result.setdefault(int(self.node_target[node]), []).append(cube)
                continue
            name = self.atoms[atom]
            stack.append((int(self.node_high[node]), cube + ((name, True),)))
            stack.append((int(self.node_low[node]), cube + ((name, False),)))
        return dict(sorted(result.items()))

    def tested_atoms(self, q: int) -> tuple[str, ...]:
        """Atoms state q's guards depend on (the reduced diagram tests exactly these)."""
        seen: set[int] = set()
        stack = [int(self.root[q])]
        while stack:
            node = stack.pop()
            if self.node_atom[node] >= 0:
                seen.add(int(self.node_atom[node]))
                stack.extend((int(self.node_low[node]), int(self.node_high[node])))
        return tuple(self.atoms[i] for i in sorted(seen))

    def successors(self, q: int) -> tuple[int, ...]:
        return tuple(self.transitions(q))

    def to_dot(self, name: str = "dfa") -> str:
        """Graphviz dot: doublecircle = accepting, grey = rejecting; edges carry guards."""
        lines = [f'digraph "{name}" {{', "  rankdir=LR;", '  init [shape=point, label=""];']
        for q in range(self.n_states):
            shape = "doublecircle" if self.accepting[q] else "circle"
            style = ', style=filled, fillcolor="#dddddd"' if self.rejecting[q] else ""
            tooltip = self.state_formulas[q].replace('"', "'")
            lines.append(f'  q{q} [shape={shape}, label="q{q}", tooltip="{tooltip}"{style}];')
        lines.append(f"  init -> q{self.initial};")
        for q in range(self.n_states):
            for target, cubes in self.transitions(q).items():
                lines.append(f'  q{q} -> q{target} [label="{guard_text(cubes, self.atoms)}"];')
        lines.append("}")
        return "\n".join(lines) + "\n"


def merge_cubes(cubes: Sequence[Cube], order: Sequence[str] = ()) -> list[Cube]:
    """A shorter equivalent disjunction: merge cubes differing in one literal's sign
    (x & a | x & !a = x) and drop cubes implied by others, until nothing changes. Literals are
    listed in `order` (atom order; others alphabetically after)."""
    current = {frozenset(c) for c in cubes}
    changed = True
    while changed:
        changed = False
        for first in list(current):
            for atom, value in first:
                partner = (first - {(atom, value)}) | {(atom, not value)}
                if partner in current:
                    current -= {first, partner}
                    current.add(first - {(atom, value)})
                    changed = True
                    break
            if changed:
                break
        implied = {c for c in current if any(o < c for o in current)}
        if implied:
            current -= implied
            changed = True
    rank = {a: i for i, a in enumerate(order)}

    def literal_key(literal: tuple[str, bool]) -> tuple[int, str]:
        return rank.get(literal[0], len(rank)), literal[0]

    merged = [tuple(sorted(c, key=literal_key)) for c in current]
    return sorted(merged, key=lambda c: (len(c), [literal_key(lit) for lit in c], c))


def guard_text(cubes: Sequence[Cube], order: Sequence[str] = ()) -> str:
    """A guard as text: `true`, or merged cubes joined by ` | `, literals by ` & `."""
    merged = merge_cubes(cubes, order)
    if any(not cube for cube in merged):
        return "true"
    return " | ".join(" & ".join(a if v else "!" + a for a, v in cube) for cube in merged)


# -- construction -------------------------------------------------------------------------------

def _progress(formula: Formula, memo: dict[Formula, Formula]) -> Formula:
    """One progression step, with the literals of the position being read left as Now nodes."""
    cached = memo.get(formula)
    if cached is not None:
        return cached
    if isinstance(formula, Const):
        result: Formula = formula
    elif isinstance(formula, Literal):
        result = Now(formula.atom, formula.positive)
    elif isinstance(formula, And):
        result = make_and(_progress(p, memo) for p in formula.parts)
    elif isinstance(formula, Or):
        result = make_or(_progress(p, memo) for p in formula.parts)
    elif isinstance(formula, Next):
        result = formula.body
    elif isinstance(formula, Eventually):
        result = make_or((_progress(formula.body, memo), formula))
    elif isinstance(formula, Until):
        result = make_or((_progress(formula.right, memo),
                          make_and((_progress(formula.left, memo), formula))))
    else:
        raise TypeError(f"cannot progress {formula!r}")
    memo[formula] = result
    return result


def _cofactor(formula: Formula, atom: str, value: bool, memo: dict[tuple[Formula, str, bool], Formula]
              ) -> Formula:
    """`formula` with the Now literals of `atom` fixed to `value` (Now only occurs under And/Or)."""
    if isinstance(formula, Now):
        return Const(formula.positive == value) if formula.atom == atom else formula
    if not isinstance(formula, And | Or):
        return formula
    key = (formula, atom, value)
    cached = memo.get(key)
    if cached is None:
        parts = (_cofactor(p, atom, value, memo) for p in formula.parts)
        cached = make_and(parts) if isinstance(formula, And) else make_or(parts)
        memo[key] = cached
    return cached


class _Builder:
    """Explores the progression automaton; diagrams are hash-consed into one node pool."""

    def __init__(self, atoms: Sequence[str], max_states: int, max_nodes: int) -> None:
        self.atoms = tuple(atoms)
        self.max_states, self.max_nodes = max_states, max_nodes
        self.rank = {a: i for i, a in enumerate(self.atoms)}
        self.states: dict[Formula, int] = {}
        self.formulas: list[Formula] = []
        self.roots: list[int] = []
        # node k: (atom rank, low, high) for a test, (-1, state, state) for a leaf
        self.nodes: list[tuple[int, int, int]] = []
        self.node_ids: dict[tuple[int, int, int], int] = {}
        self.progress_memo: dict[Formula, Formula] = {}
        self.cofactor_memo: dict[tuple[Formula, str, bool], Formula] = {}
        self.expand_memo: dict[Formula, int] = {}
        self.now_memo: dict[Formula, int | None] = {}
        self.queue: deque[int] = deque()

    def first_now(self, formula: Formula) -> int | None:
        """Smallest atom rank among the Now literals of `formula` (memoised per formula)."""
        if isinstance(formula, Now):
            return self.rank[formula.atom]
        if not isinstance(formula, And | Or):
            return None
        if formula in self.now_memo:
            return self.now_memo[formula]
        ranks = [r for r in map(self.first_now, formula.parts) if r is not None]
        found = min(ranks) if ranks else None
        self.now_memo[formula] = found
        return found

    def node(self, entry: tuple[int, int, int]) -> int:
        found = self.node_ids.get(entry)
        if found is None:
            if len(self.nodes) >= self.max_nodes:
                raise DFATooLarge(f"more than {self.max_nodes} guard nodes")
            found = len(self.nodes)
            self.nodes.append(entry)
            self.node_ids[entry] = found
        return found

    def state(self, formula: Formula) -> int:
        found = self.states.get(formula)
        if found is None:
            if len(self.formulas) >= self.max_states:
                raise DFATooLarge(f"more than {self.max_states} DFA states before minimisation")
            found = len(self.formulas)
            self.states[formula] = found
            self.formulas.append(formula)
            self.queue.append(found)
        return found

    def expand(self, formula: Formula) -> int:
        """Ordered decision diagram of a progressed formula; leaves are successor states."""
        cached = self.expand_memo.get(formula)
        if cached is not None:
            return cached
        rank = self.first_now(formula)
        if rank is None:
            target = self.state(disjunctive_normal_form(formula))
            result = self.node((-1, target, target))
        else:
            atom = self.atoms[rank]
            low = self.expand(_cofactor(formula, atom, False, self.cofactor_memo))
            high = self.expand(_cofactor(formula, atom, True, self.cofactor_memo))
            result = low if low == high else self.node((rank, low, high))
        self.expand_memo[formula] = result
        return result

    def explore(self, initial: Formula) -> None:
        self.state(initial)
        while self.queue:
            q = self.queue.popleft()
            if self.formulas[q] == TRUE:
                root = self.node((-1, q, q))  # accepting: absorbing
            else:
                root = self.expand(_progress(self.formulas[q], self.progress_memo))
            self.roots.append(root)
            assert len(self.roots) == q + 1  # states are expanded in creation order


def _leaf_targets(nodes: list[tuple[int, int, int]]) -> list[frozenset[int]]:
    """For every node of a pool, the set of leaf targets below it (children precede parents in
    a pool, since nodes are created bottom-up)."""
    targets: list[frozenset[int]] = []
    for rank, low, high in nodes:
        targets.append(frozenset((low,)) if rank < 0 else targets[low] | targets[high])
    return targets


def _reduce_over_blocks(nodes: list[tuple[int, int, int]], roots: list[int], block: np.ndarray
                        ) -> tuple[list[tuple[int, int, int]], list[int]]:
    """Each state's diagram with leaves replaced by blocks, reduced and hash-consed into a fresh
    pool: equal functions (letter -> block) get equal node ids (canonical for the atom order)."""
    pool: dict[tuple[int, int, int], int] = {}
    entries: list[tuple[int, int, int]] = []
    memo: dict[int, int] = {}

    def intern(entry: tuple[int, int, int]) -> int:
        found = pool.get(entry)
        if found is None:
            found = len(entries)
            pool[entry] = found
            entries.append(entry)
        return found

    def reduce(k: int) -> int:
        found = memo.get(k)
        if found is not None:
            return found
        rank, low, high = nodes[k]
        if rank < 0:
            b = int(block[low])
            found = intern((-1, b, b))
        else:
            lo, hi = reduce(low), reduce(high)
            found = lo if lo == hi else intern((rank, lo, hi))
        memo[k] = found
        return found

    return entries, [reduce(r) for r in roots]


def _minimise(nodes: list[tuple[int, int, int]], roots: list[int], accepting: np.ndarray
              ) -> tuple[np.ndarray, list[tuple[int, int, int]], list[int]]:
    """Moore partition refinement over the symbolic transitions, starting from
    {accepting, non-accepting}. Returns (block of each state, reduced node pool over blocks,
    root node of each block)."""
    n = len(roots)
    block = np.unique(np.where(accepting, 0, 1), return_inverse=True)[1].astype(np.int64)
    n_blocks = int(block.max()) + 1
    while True:
        entries, reduced_roots = _reduce_over_blocks(nodes, roots, block)
        signatures: dict[tuple[int, int], int] = {}
        new_block = np.empty(n, dtype=np.int64)
        for q in range(n):
            new_block[q] = signatures.setdefault((int(block[q]), reduced_roots[q]), len(signatures))
        if len(signatures) == n_blocks:
            block_roots = [0] * n_blocks
            for q in range(n):
                block_roots[int(block[q])] = reduced_roots[q]
            return block, entries, block_roots
        block, n_blocks = new_block, len(signatures)


def _backward_closure(successors: list[set[int]], seed: np.ndarray, every: bool) -> np.ndarray:
    """Least fixpoint from `seed`: add q when every successor (every=True) or some successor
    (every=False) is in the set. Worklist over the reverse graph, linear in the edges."""
    inside = seed.copy()
    predecessors: list[list[int]] = [[] for _ in successors]
    missing = np.array([len(t) for t in successors], dtype=np.int64)
    for q, targets in enumerate(successors):
        for t in targets:
            predecessors[t].append(q)
    work: list[int] = np.flatnonzero(inside).tolist()
    while work:
        t = int(work.pop())
        for q in predecessors[t]:
            if inside[q]:
                continue
            missing[q] -= 1
            if not every or missing[q] == 0:
                inside[q] = True
                work.append(q)
    return inside


def dfa_from_formula(formula: Formula, atoms: Sequence[str] | None = None, max_states: int | None = None,
                     max_nodes: int | None = None) -> DFA:
    """Translate a formula into its complete minimal DFA over `atoms` (default: the formula's
    atoms in order of first occurrence; extra atoms are allowed and simply never tested).
    Raises DFATooLarge when the exploration exceeds `max_states` or `max_nodes`."""
    atom_order = tuple(atoms) if atoms is not None else atoms_in_order(formula)
    missing = set(atoms_in_order(formula)) - set(atom_order)
    if missing:
        raise ValueError(f"atoms {sorted(missing)} of the formula are not in the atom order")
    builder = _Builder(atom_order, MAX_STATES if max_states is None else max_states,
                       MAX_NODES if max_nodes is None else max_nodes)
    builder.explore(disjunctive_normal_form(canonical(formula)))
    below = _leaf_targets(builder.nodes)
    successors = [set(below[r]) for r in builder.roots]
    # Valid obligations (hold on every continuation): least fixpoint of
    # valid(q) = (q is `true`) or every successor of q is valid.
    valid = _backward_closure(successors, np.array([f == TRUE for f in builder.formulas]), every=True)
    roots = list(builder.roots)
    nodes = list(builder.nodes)
    for valid_state in np.flatnonzero(valid):
        roots[valid_state] = len(nodes)  # valid obligations are accepting and absorbing
        nodes.append((-1, int(valid_state), int(valid_state)))
    block, pool, block_roots = _minimise(nodes, roots, valid)

    # Number the minimal states breadth-first from the initial state (deterministic ids).
    pool_below = _leaf_targets(pool)

    def targets_of(b: int) -> list[int]:
        return sorted(pool_below[block_roots[b]])

    order = {int(block[0]): 0}
    queue = deque([int(block[0])])
    while queue:
        b = queue.popleft()
        for t in targets_of(b):
            if t not in order:
                order[t] = len(order)
                queue.append(t)
    n_states = len(order)
    accepting = np.zeros(n_states, dtype=bool)
    representative: list[Formula | None] = [None] * n_states
    for q in range(len(roots)):
        new = order.get(int(block[q]))
        if new is None:
            continue
        accepting[new] = bool(valid[q])
        if representative[new] is None:
            representative[new] = builder.formulas[q]

    # Remap the node pool to the new state numbers (nodes of unreachable blocks are harmless).
    node_atom = np.array([e[0] for e in pool], dtype=np.int64)
    node_low = np.array([e[1] if e[0] >= 0 else 0 for e in pool], dtype=np.int64)
    node_high = np.array([e[2] if e[0] >= 0 else 0 for e in pool], dtype=np.int64)
    node_target = np.array([order.get(e[1], -1) if e[0] < 0 else -1 for e in pool], dtype=np.int64)
    root = np.empty(n_states, dtype=np.int64)
    for b, new in order.items():
        root[new] = block_roots[b]

    # Rejecting: acceptance unreachable (backward reachability from accepting states).
    forward = [{order[b] for b in pool_below[int(root[q])]} for q in range(n_states)]
    can_accept = _backward_closure(forward, accepting, every=False)
    rejecting = ~can_accept
    for array in (accepting, rejecting, root, node_atom, node_low, node_high, node_target):
        array.setflags(write=False)
    formulas = tuple(format_formula(f) if f is not None else "?" for f in representative)
    return DFA(atoms=atom_order, n_states=n_states, initial=0, accepting=accepting, rejecting=rejecting,
               root=root, node_atom=node_atom, node_low=node_low, node_high=node_high,
               node_target=node_target, state_formulas=formulas)


def build_dfa(spec: Spec) -> DFA:
    """The minimal DFA of `spec.formula` over the atoms it uses (InputError when it is too large).
    A spec's compilation on its town holds it (policies/logic/compiled.py: compile_spec)."""
    try:
        return dfa_from_formula(spec.formula, spec.formula_atoms)
    except DFATooLarge as exc:
        raise InputError(spec.source_path or spec.name, "formula", f"the formula is too large to "
                         f"translate ({exc})", "split the task or simplify the formula") from None
