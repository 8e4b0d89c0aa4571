"""Observation symbols of the belief MDP and the finite 'suffix' abstraction of belief space.

An observation symbol o = (incident, h, e) has a likelihood vector L_o[θ] = P(h, e | θ, inc) and
an update matrix W_o: the filter is the linear-fractional map f_o(b) = b W_o / (b W_o 1)
(Bayes: W_o = diag(L_o) T[inc][h][e]; the authors' "paper" rule: W_o = T[inc][h][e], with the
probability of o still b·L_o). Symbols with W_o = c·I and a uniform likelihood (the default
model's 'none' incident) leave the belief unchanged and are not counted as belief-changing for the
cells; the belief itself is always advanced by the one filter, `TrustPOMDP.belief_update`, which
the vehicle, exact evaluation and the model engine use too (it returns the belief bit for bit for
such symbols, so every user holds the same float64 belief).

Suffix cells: a cell is a word w of at most k belief-changing symbols and stands for the polytope
P_w = f_w(simplex) = conv{f_w(e_i)}. A belief whose history of belief-changing symbols ends in w
lies in P_w (f_{uw}(Δ) ⊆ f_w(Δ)), so the cell of the last k symbols always contains the belief.
Because f_o maps the hull of points to the hull of their images, the vertices of P_w are the
images of the simplex corners; a belief atom (affine in b) is all-true / all-false / mixed on a
cell by its signs at the vertices.

The simplex here is the face of the hidden states reachable from the initial belief's support
(`reachable_states`): every belief of every history is supported there (b W_o is supported on the
one-step successors of b's support), so the argument above holds with that face for Δ. With a full
support (the uniform prior of one driver) the face is the whole simplex. It matters for a type-aware
model (policies/belief/driver_types.py): a type whose trust never moves from its initial level
adds one corner, not seven, and corners such as "that type at trust 7", fixed points of every
update that would keep a belief atom possible in every cell, are not vertices of any cell.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np

from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP

# A vertex of a cell this close to an atom's hyperplane counts as either side. The vertices are
# float images of the simplex corners through up to k filter steps; each step is within γ_{3n}
# relative (policies/logic/labelling.py), about 2e-15 for n = 7, so 1e-12 leaves a factor of ~50
# for k <= 8 steps even if every step's error were amplified tenfold (docs/synthesis.md).
LABEL_TOLERANCE = 1e-12


@dataclass(frozen=True, eq=False)
class ObservationSymbols:
    """Symbols with nonzero probability for some trust level, per incident.

    incident[o], human_action[o], performance[o]: the symbol's parts.
    likelihood[o]: P(o | θ) as a vector over θ; update[o]: W_o; identity[o]: W_o = c·I and L_o = c·1.
    by_incident[i]: symbol ids of incident i. changing_id[o]: index among belief-changing symbols
    (-1 for identity symbols).
    """

    pomdp: TrustPOMDP
    rule: BeliefRule
    incident: np.ndarray
    human_action: np.ndarray
    performance: np.ndarray
    likelihood: np.ndarray      # [n_symbols, n_trust]
    update: np.ndarray          # [n_symbols, n_trust, n_trust]
    identity: np.ndarray        # bool [n_symbols]
    by_incident: tuple[tuple[int, ...], ...]
    changing_id: np.ndarray     # [n_symbols]

    @property
    def n_symbols(self) -> int:
        return int(self.incident.size)

    @property
    def n_changing(self) -> int:
        return int((~self.identity).sum())

    @functools.cached_property
    def fill_orders(self) -> tuple[tuple[np.ndarray, ...], ...]:
        """`fill_orders` of every symbol's every coordinate: [o][j] -> [k, n] (the minimum's
        orders are these reversed; policies/synthesis/completion_value.py), computed once."""
        out = []
        for o in range(self.n_symbols):
            update = self.update[o]
            out.append(tuple(fill_orders(update[:, j], update.sum(axis=1)) for j in range(update.shape[1])))
        return tuple(out)


def fill_orders(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """int [k, n]: the orders of decreasing a_i - λ d_i over every λ (one per interval between the
    crossings of the lines, at the crossings, just beside them, and at both ends): the greedy fill
    in one of them maximises (a - λ d)·b over a box-simplex for every λ. The crossings are float
    quotients, so the orders just beside each one are taken too; extra orders only cost time (every
    greedy vertex is a point of the box), a missing one would cost soundness."""
    n = a.size
    crossings = [(a[i] - a[k]) / (d[i] - d[k]) for i in range(n) for k in range(i + 1, n) if d[i] != d[k]]
    points = np.sort(np.array(crossings + [0.0]))
    nudge = 1e-9 * np.maximum(np.abs(points), 1.0)
    tests = np.concatenate([points, points - nudge, points + nudge, (points[1:] + points[:-1]) / 2,
                            [points[0] - 1.0, points[-1] + 1.0]])
    # every λ's order at once (the same float operations per λ as one at a time); the distinct
    # orders in lexicographic order (a lexsort and a neighbour comparison: np.unique over rows
    # costs ten times more)
    orders = np.argsort(-(a[None, :] - tests[:, None] * d[None, :]), axis=1, kind="stable")
    orders = orders[np.lexsort(orders.T[::-1])]
    distinct = np.ones(len(orders), dtype=bool)
    distinct[1:] = (orders[1:] != orders[:-1]).any(axis=1)
    return orders[distinct].astype(np.int64)


def observation_symbols(pomdp: TrustPOMDP, rule: BeliefRule = "bayes") -> ObservationSymbols:
    if rule not in ("bayes", "paper"):
        raise ValueError(f"unknown belief rule {rule!r}; use 'bayes' or 'paper'")
    driver = pomdp.driver
    n_inc = len(driver.incident_types)
    performances = (0, 1) if driver.depends_on_performance else (0,)
    rows: list[tuple[int, int, int]] = []
    likelihoods, updates, identities = [], [], []
    by_incident: list[list[int]] = [[] for _ in range(n_inc)]
    for i in range(n_inc):
        for h in (0, 1):
            for e in performances:
                likelihood = np.asarray(pomdp.observation_likelihood[i, h, e], dtype=float)
                if not (likelihood > 0).any():
                    continue
                if rule == "bayes":
                    update = np.asarray(pomdp.weighted_transition[i, h, e], dtype=float)
                else:
                    update = np.asarray(driver.trust_transition[i, h, e], dtype=float)
                # The filter returns the belief unchanged (exactly c·I) and the probability is the
                # same for every belief (a uniform likelihood).
                identity = bool(pomdp.preserves_belief(rule)[i, h, e] and pomdp.uniform_likelihood[i, h, e])
                by_incident[i].append(len(rows))
                rows.append((i, h, e))
                likelihoods.append(likelihood)
                updates.append(update)
                identities.append(identity)
    identity_array = np.array(identities, dtype=bool)
    changing_id = np.full(len(rows), -1, dtype=np.int64)
    changing_id[~identity_array] = np.arange(int((~identity_array).sum()))
    parts = np.array(rows, dtype=np.int64).reshape(-1, 3)
    return ObservationSymbols(
        pomdp=pomdp, rule=rule, incident=parts[:, 0], human_action=parts[:, 1], performance=parts[:, 2],
        likelihood=np.array(likelihoods), update=np.array(updates), identity=identity_array,
        by_incident=tuple(tuple(s) for s in by_incident), changing_id=changing_id)


def apply_symbol(beliefs: np.ndarray, symbols: ObservationSymbols, symbol: np.ndarray | int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(f_o(b), P(o | b)) for each row, by the one filter `TrustPOMDP.belief_update` (no shortcuts)."""
    beliefs = np.atleast_2d(beliefs)
    symbol = np.broadcast_to(np.asarray(symbol), (beliefs.shape[0],))
    return symbols.pomdp.belief_update(beliefs, symbols.incident[symbol], symbols.human_action[symbol],
                                       symbols.performance[symbol], rule=symbols.rule)


@dataclass(frozen=True, eq=False)
class SuffixCells:
    """All words of at most k belief-changing symbols (cell 0 = the empty word = the simplex).

    vertices[c]: [n_trust, n_trust], row i = f_w(e_i) (the corners of P_w).
    next_cell[c, o]: cell of the last k belief-changing symbols after reading symbol o
    (identity symbols keep the cell).
    successor_vertices are not stored: `image_vertices(c, o)` gives the corners of f_{wo}(Δ) ⊆ P_next.
    """

    k: int
    words: tuple[tuple[int, ...], ...]
    vertices: np.ndarray
    next_cell: np.ndarray

    @property
    def n_cells(self) -> int:
        return len(self.words)


def _normalise_rows(matrix: np.ndarray) -> np.ndarray:
    total = matrix.sum(axis=-1, keepdims=True)
    return np.divide(matrix, total, out=np.zeros_like(matrix), where=total > 0)


def reachable_states(symbols: ObservationSymbols) -> np.ndarray:
    """bool [n_trust]: the hidden states some history can give positive belief, from the initial
    belief's support through the support of every symbol's update matrix."""
    reached = np.asarray(symbols.pomdp.initial_belief, dtype=float) > 0
    step = np.asarray((symbols.update > 0).any(axis=0))                   # [θ, θ']
    while True:
        grown = reached | step[reached].any(axis=0)
        if (grown == reached).all():
            return reached
        reached = grown


def suffix_cells(symbols: ObservationSymbols, k: int) -> SuffixCells:
    if k < 0:
        raise ValueError("suffix length k must be >= 0")
    changing = np.flatnonzero(~symbols.identity).tolist()
    # Words are numbered level by level, each level's words in the order of their prefix and then
    # of their last symbol (itertools.product's order). The corners of the reachable face; an
    # unreachable corner is a zero row, absent from every cell. A level's images are one stacked
    # matmul per symbol (numpy's matmul calls the same BLAS product per stacked matrix, so each is
    # the single product's, bit for bit).
    words = [word for length in range(k + 1) for word in itertools.product(changing, repeat=length)]
    level = np.diag(reachable_states(symbols).astype(float))[None]          # [words, θ, θ]
    levels = [level]
    for _ in range(k if changing else 0):   # without a belief-changing symbol the one cell is the simplex
        images = np.stack([level @ symbols.update[o] for o in changing], axis=1)   # [w, o, θ, θ]
        level = _normalise_rows(images.reshape(-1, *images.shape[2:]))
        levels.append(level)
    # A word of length L is cell start[L] + its digits (positions in `changing`) read in base n.
    # Reading a belief-changing symbol appends its digit, the oldest dropping out of a word of k;
    # an identity symbol keeps the cell (and with k = 0 every symbol keeps the one cell).
    n = len(changing)
    start = np.cumsum([0] + [n ** length for length in range(k + 1)])
    next_cell = np.repeat(np.arange(len(words), dtype=np.int64)[:, None], symbols.n_symbols, axis=1)
    for length in range(k + 1 if k else 0):
        cells = np.arange(start[length], start[length + 1], dtype=np.int64)
        kept = cells - start[length] if length < k else (cells - start[length]) % n ** (k - 1)
        for digit, o in enumerate(changing):
            next_cell[cells, o] = start[min(length + 1, k)] + kept * n + digit
    return SuffixCells(k=k, words=tuple(words), vertices=np.concatenate(levels), next_cell=next_cell)


def vertex_mask(cells: SuffixCells) -> np.ndarray:
    """bool [n_cells, n_trust]: which corner images exist (nonzero rows)."""
    return cells.vertices.sum(axis=-1) > 0


def image_label_status(cells: SuffixCells, symbols: ObservationSymbols, coeffs: np.ndarray,
                       offsets: np.ndarray) -> np.ndarray:
    """int8 [n_atoms, n_cells, n_symbols]: status of each atom j (offsets[j] - coeffs[j]·b < 0) on
    f_o(P_c); `coeffs` [n_atoms, n_trust], `offsets` [n_atoms].

    1 all true, 0 all false, 2 mixed (either value possible). Vertices with zero weight (P(o|v)=0)
    are dropped (they contribute nothing to the hull of the image). Each symbol's images are
    computed once for all atoms.
    """
    status = np.zeros((len(offsets), cells.n_cells, symbols.n_symbols), dtype=np.int8)
    for o in range(symbols.n_symbols if len(offsets) else 0):
        image = _normalise_rows(cells.vertices @ symbols.update[o])         # [c, v, θ]
        valid = image.any(axis=-1)
        for j, (coeff, offset) in enumerate(zip(coeffs, offsets, strict=True)):
            value = offset - np.einsum("cvk,k->cv", image, coeff)
            true_somewhere = (valid & (value < LABEL_TOLERANCE)).any(axis=1)
            false_somewhere = (valid & (value > -LABEL_TOLERANCE)).any(axis=1)
            status[j, :, o] = np.where(true_somewhere & false_somewhere, 2, np.where(true_somewhere, 1, 0))
    return status
