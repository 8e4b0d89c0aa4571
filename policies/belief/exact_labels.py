"""Belief labels decided exactly where floating point cannot decide them.

A belief atom is `c·b > offset` on the belief of the model's exact Bayes filter: the model's
numbers are the decimals they print as (`decimal`: Fraction(repr(x)), what a model or spec file
written from them holds), the prior is those decimals normalised to sum 1 (the uniform prior is
exactly 1/n), and every step is the exact linear-fractional map b W_o / (b W_o 1) of the symbol
o = (incident, h, e) (W_o = diag(L_o) T for Bayes, T for the authors' "paper" rule).

Every caller advances the float filter (TrustPOMDP.belief_update) and reads the float label when it
is decided: when |c·b̂ - offset| exceeds `FloatLabelBound.margin`, a bound on |c·b - c·b̂| for the
exact belief b of the same history. Elsewhere the label is decided exactly, from the history's
word (the sequence of symbols whose exact update is not c·I): `ExactLabels.truth`.

The bound. Let d(x, y) = log max_i(x_i/y_i) - log min_i(x_i/y_i) (Hilbert's projective metric on
vectors of one support). A nonnegative matrix never increases d (each (xW)_j is a nonnegative
combination of the x_i, so its ratio to (yW)_j lies between the smallest and the largest x_i/y_i),
and scaling leaves it unchanged. One float step of the filter multiplies each component of the
exact image of b̂ under the float matrix by (1 + θ_n)(1 + δ) (an n-term product-sum and the division;
the row sum is one scalar for every component), and the float matrix is the exact W_o times
(1 + ε) entrywise, |ε| <= ε_W (computed exactly per symbol from the model). So each step adds at
most σ = log((1+γ_n)(1+u)/((1-γ_n)(1-u))) + log((1+ε_W)/(1-ε_W)) to d, and after a word of k
symbols d(b̂, b) <= D = d0 + k σ (d0: the float prior against the exact one). Both sides summing to
S = Σb̂ and 1, every b_i/b̂_i lies in [e^-D / S, e^D / S], within ρ of 1; so
|c·b - fl(c·b̂)| <= (ρ + γ_n + ε_c (1 + ρ)) Σ|c_i| b̂_i, plus |offset - fl(offset)| for the
offset. The margin is twice that (the bound itself is evaluated in floats). Assumed, as in
Higham's bounds: no underflow in the filter.
"""

from __future__ import annotations

import math
from dataclasses import InitVar, dataclass, field
from fractions import Fraction

import numpy as np

from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.driver_types import TypeLiftedModel
from trustroute.policies.logic.labelling import UNIT_ROUNDOFF, Labeller, atom_values, gamma
from trustroute.policies.model import trust_pomdp
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP, row_blocks


def decimal(value: float) -> Fraction:
    """The decimal a float prints as (the shortest that reads back as it), exactly."""
    return Fraction(repr(float(value)))


def _normalised(values) -> list[Fraction]:
    entries = [decimal(v) for v in values]
    total = sum(entries, Fraction(0))
    return [e / total for e in entries]


def exact_prior(driver: DriverModel) -> tuple[Fraction, ...]:
    """The model's prior belief exactly: each entry the decimal it prints as, normalised; a
    type-aware model's λ ⊗ b0 block by block, from the type weights' decimals and each type's own
    prior's (its float products round: a type of weight 0.5 with 1/3 on three levels would weigh a
    hair under 1/2, and a label on exactly 1/2 would flip)."""
    if isinstance(driver, TypeLiftedModel) and driver.type_initial:
        return tuple(w * b for w, block in zip(_normalised(driver.type_prior), driver.type_initial,
                                               strict=True) for b in _normalised(block))
    return tuple(_normalised(driver.initial_belief))


def _relative_gap(approximate: float, exact: Fraction) -> float:
    """|approximate - exact| / |exact|, rounded up; inf when exact is 0 and approximate is not.
    In integers: Python's int / int is correctly rounded, as float(Fraction) is."""
    if exact == 0:
        return 0.0 if approximate == 0 else math.inf
    numerator, denominator = float(approximate).as_integer_ratio()
    difference = abs(numerator * exact.denominator - exact.numerator * denominator)
    gap = difference / (denominator * abs(exact.numerator))
    return gap * (1 + 4 * UNIT_ROUNDOFF)


def symbol_code(incident: np.ndarray | int, human_action: np.ndarray | int,
                performance: np.ndarray | int) -> np.ndarray:
    """One integer per observation symbol (incident, h, e)."""
    return (np.asarray(incident, dtype=np.int64) * 2 + np.asarray(human_action, dtype=np.int64)) * 2 \
        + np.asarray(performance, dtype=np.int64)


# A scoped filter compacts its words only past this many (below, forgetting saves next to nothing).
COMPACT_AT_LEAST = 4096


@dataclass(eq=False)
class ExactFilter:
    """The exact filter of `pomdp` under `rule`, its words and the float filter's distance to it.

    Words are interned: id 0 is the empty word; `extend` gives the id of word + symbol (the same id
    for a symbol whose exact update is c·I). `belief(word)` is memoised. `like`: a filter of another
    model under the same rule whose symbol matrices, if that model's arrays are this one's (a
    driver population under another type prior), are taken rather than converted again."""

    pomdp: TrustPOMDP
    rule: BeliefRule
    like: InitVar[ExactFilter | None] = None
    matrices: dict[int, tuple[tuple[Fraction, ...], ...]] = field(init=False)
    changing: np.ndarray = field(init=False)        # bool [n_codes]: exact update is not c·I
    prior: tuple[Fraction, ...] = field(init=False)
    prior_distance: float = field(init=False)       # d0
    step_distance: float = field(init=False)        # σ
    # The words, by id, in arrays of doubling capacity (a word is a few dozen bytes, not a few
    # Python objects: an unfolding interns one per history): its prefix without the last symbol,
    # that symbol's code (-1: the empty word) and its length.
    _parent: np.ndarray = field(init=False)
    _code: np.ndarray = field(init=False)
    _length: np.ndarray = field(init=False)
    _size: int = field(init=False)                  # words interned: ids 0 .. _size - 1
    _kept: int = field(init=False)                  # words the last `compact` kept
    _ids: dict[int, int] = field(init=False)        # word * n_codes + code -> word id
    _beliefs: dict[int, tuple[Fraction, ...]] = field(init=False)

    def __post_init__(self, like: ExactFilter | None) -> None:
        if like is not None and like.rule == self.rule and same_symbol_arrays(like.pomdp, self.pomdp):
            self.matrices, self.changing = dict(like.matrices), like.changing.copy()
            self.step_distance = like.step_distance
        else:
            self.matrices, self.changing, worst = exact_symbol_matrices(self.pomdp, self.rule)
            g, u = gamma(self.pomdp.n_trust), UNIT_ROUNDOFF
            self.step_distance = (math.log((1 + g) * (1 + u) / ((1 - g) * (1 - u)))
                                  + (math.log((1 + worst) / (1 - worst)) if worst < 1 else math.inf))
        u = UNIT_ROUNDOFF
        self.prior = exact_prior(self.pomdp.driver)
        ratios = [Fraction(float(f)) / b for f, b in zip(self.pomdp.initial_belief, self.prior,
                                                          strict=True) if b != 0]
        self.prior_distance = (float(max(ratios) / min(ratios)) if ratios else 1.0)
        self.prior_distance = math.log(self.prior_distance) * (1 + 4 * u) + 4 * u
        self._parent, self._code, self._length = (np.zeros(64, dtype=np.int64) for _ in range(3))
        self._code[0] = -1
        self._size = self._kept = 1
        self._ids, self._beliefs = {}, {0: self.prior}

    def scoped(self) -> ExactFilter:
        """A filter of the same model and rule with words of its own, for one owner that may
        `compact` them (its symbol matrices are this one's)."""
        return ExactFilter(pomdp=self.pomdp, rule=self.rule, like=self)

    def extend(self, words: np.ndarray, codes: np.ndarray) -> np.ndarray:
        """Word ids of words[i] + codes[i] (vectorised; an unchanging symbol keeps the word)."""
        words = np.asarray(words, dtype=np.int64)
        codes = np.broadcast_to(np.asarray(codes, dtype=np.int64), words.shape)
        out = words.copy()
        moving = self.changing[codes]
        if not moving.any():
            return out
        if words.size == 1:   # one history (an episode at a time): no pairs to deduplicate
            out[moving] = self.extend_one(int(words[moving][0]), int(codes[moving][0]))
            return out
        # one integer per (word, code) pair: a 1-D unique is many times cheaper than rows'
        n_codes = self.changing.size
        keys, inverse = np.unique(words[moving] * n_codes + codes[moving], return_inverse=True)
        known = self._ids.get
        ids = np.array([known(key, 0) for key in keys.tolist()], dtype=np.int64)
        new = ids == 0      # id 0 is the empty word's, never an extension's
        if new.any():
            ids[new] = self._add_all(keys[new] // n_codes, keys[new] % n_codes)
            self._ids.update(zip(keys[new].tolist(), ids[new].tolist(), strict=True))
        out[moving] = ids[inverse.ravel()]
        return out

    def extend_one(self, word: int, code: int) -> int:
        """The id of word + the symbol of `code` (`extend` for one history)."""
        if not self.changing[code]:
            return word
        key = word * self.changing.size + code
        found = self._ids.get(key)
        if found is None:
            found = self._ids[key] = int(self._add_all(np.array([word]), np.array([code]))[0])
        return found

    def _add_all(self, words: np.ndarray, codes: np.ndarray) -> np.ndarray:
        """New words, words[i] + the changing symbol codes[i] (none interned yet), in order; their
        ids (never 0, the empty word's). The caller enters them in `_ids`."""
        begin, end = self._size, self._size + words.size
        if end > self._length.size:   # doubling: adding a word never copies them all
            capacity = max(2 * self._length.size, end)
            for array in (self._parent, self._code, self._length):
                # in place (realloc, the new rows zero): the old and the new arrays are never held
                # at once; no view of them outlives a call of this filter's (refcheck is for those)
                array.resize(capacity, refcheck=False)
        self._parent[begin:end] = words
        self._code[begin:end] = codes
        self._length[begin:end] = self._length[words] + 1
        self._size = end
        return np.arange(begin, end, dtype=np.int64)

    def compact(self, words: np.ndarray) -> np.ndarray:
        """Forget the words that are neither in `words` nor a prefix of one; the ids of `words`
        after it. Ids keep their order (a word's new id is the number of kept words before it), so
        whatever sorts or groups rows by word does so as before, and a word interned later still
        gets a larger id. Only a filter of one owner (`scoped`) is compacted, by that owner, with
        every word it still holds: those are the only words it extends from then on, so the
        lookup of extensions keeps theirs alone, at every call; the words themselves are
        renumbered once they have doubled since the last time (a constant per word interned)."""
        if self.pomdp.exact_filters.get(self.rule) is self:
            raise ValueError("the model's shared exact filter is never compacted: compact a scoped() one")
        words = np.asarray(words, dtype=np.int64)
        held = np.zeros(self._size, dtype=bool)
        held[words] = True
        if self._size > max(2 * self._kept, COMPACT_AT_LEAST):
            words, held = self._forget(words, held)
        extensions = np.flatnonzero(held[self._parent[:self._size]])
        extensions = extensions[extensions > 0]
        n_codes = self.changing.size
        self._ids = dict(zip((self._parent[extensions] * n_codes + self._code[extensions]).tolist(),
                             extensions.tolist(), strict=True))
        return words

    def _forget(self, words: np.ndarray, held: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Keep the `held` words and their prefixes, renumbered in order; (`words`, `held`) in the
        new ids."""
        keep = held.copy()
        keep[0] = True
        current = np.unique(self._parent[words])
        while current.size:
            current = current[~keep[current]]
            keep[current] = True
            current = np.unique(self._parent[current])
        new_id = np.cumsum(keep) - 1
        kept = np.flatnonzero(keep)
        self._parent, self._code, self._length = (new_id[self._parent[kept]], self._code[kept].copy(),
                                                  self._length[kept].copy())
        self._size = self._kept = int(kept.size)
        self._beliefs = {int(new_id[w]): b for w, b in self._beliefs.items() if keep[w]}
        return new_id[words], held[kept]

    def lengths(self, words: np.ndarray) -> np.ndarray:
        return self._length[np.asarray(words, dtype=np.int64)]

    def belief(self, word: int) -> tuple[Fraction, ...]:
        """The exact belief after `word` (all zeros after a word of probability 0)."""
        chain = []
        while word not in self._beliefs:
            chain.append(word)
            word = int(self._parent[word])
        belief = self._beliefs[word]
        for w in reversed(chain):
            matrix = self.matrices[int(self._code[w])]
            n = len(belief)
            image = [sum((belief[k] * matrix[k][m] for k in range(n) if belief[k]), Fraction(0))
                     for m in range(n)]
            total = sum(image, Fraction(0))
            belief = tuple(v / total for v in image) if total else tuple(image)
            self._beliefs[w] = belief
        return belief

    def same_belief(self, one: int, other: int) -> bool:
        """Whether two words lead to one exact belief (then every label after any further symbols
        is the same on both)."""
        return one == other or self.belief(one) == self.belief(other)

    def distance(self, words: np.ndarray) -> np.ndarray:
        """D per word: the bound on Hilbert's distance between the float and the exact belief."""
        return self.prior_distance + self.lengths(words) * self.step_distance


def same_symbol_arrays(one: TrustPOMDP, other: TrustPOMDP) -> bool:
    """Whether two models' exact symbol matrices are the same: equal likelihoods and transitions
    (their priors may differ)."""
    a, b = one.driver, other.driver
    return (len(a.incident_types) == len(b.incident_types)
            and all(np.array_equal(x, y) for x, y in ((a.takeover_probability, b.takeover_probability),
                                                      (a.failure_probability, b.failure_probability),
                                                      (a.trust_transition, b.trust_transition))))


def exact_symbol_matrices(pomdp: TrustPOMDP, rule: BeliefRule
                           ) -> tuple[dict[int, tuple[tuple[Fraction, ...], ...]], np.ndarray, float]:
    """(exact matrix W_o per symbol code, bool per code: W_o is not c·I, the largest relative gap
    of the float matrices to the exact ones) of `pomdp` under `rule`.

    A model's arrays hold few distinct numbers (a population's lifted transitions are mostly the
    zeros between types), so each decimal is computed once per number (`_Exact`)."""
    driver, n = pomdp.driver, pomdp.n_trust
    floats = (pomdp.weighted_transition if rule == "bayes" else driver.trust_transition)
    n_inc = len(driver.incident_types)
    one = Fraction(1)
    exact = _Exact()
    matrices, worst = {}, 0.0
    changing = np.zeros(n_inc * 4, dtype=bool)
    for i in range(n_inc):
        takeover = [exact.decimal(t) for t in driver.takeover_probability[i].tolist()]
        failure = [exact.decimal(f) for f in driver.failure_probability[i].tolist()]
        for h in (0, 1):
            for e in (0, 1):
                like = [(takeover[k] if h else one - takeover[k])
                        * (failure[k] if e else one - failure[k]) for k in range(n)]
                weights = like if rule == "bayes" else [one] * n
                rows = driver.trust_transition[i, h, e].tolist()
                matrix = tuple(tuple(exact.product(weights[k], value) for value in rows[k]) for k in range(n))
                code = int(symbol_code(i, h, e))
                matrices[code] = matrix
                changing[code] = not _scaled_identity(matrix)
                if any(like):
                    approximate = floats[i, h, e].tolist()
                    worst = max(worst, max(_relative_gap(approximate[k][m], matrix[k][m])
                                           for k in range(n) for m in range(n)))
    return matrices, changing, worst


class _Exact:
    """The decimals of one conversion, each computed once per distinct float; a zero's products
    are the one zero."""

    def __init__(self) -> None:
        self.decimals: dict[float, Fraction] = {}

    def decimal(self, value: float) -> Fraction:
        found = self.decimals.get(value)
        if found is None:
            found = self.decimals[value] = decimal(value)
        return found

    def product(self, weight: Fraction, value: float) -> Fraction:
        return ZERO if value == 0 else weight * self.decimal(value)


ZERO = Fraction(0)


def _scaled_identity(matrix: tuple[tuple[Fraction, ...], ...]) -> bool:
    n = len(matrix)
    return (matrix[0][0] > 0 and all(matrix[k][k] == matrix[0][0] for k in range(n))
            and all(matrix[k][m] == 0 for k in range(n) for m in range(n) if k != m))


def _labeller_constants(labeller: Labeller) -> tuple:
    """(coeffs, offsets, coeff_gap, offset_gap) of ExactLabels: the decimals of `labeller`'s
    coefficients and offsets and their float gaps, a pure function of the labeller."""
    c = labeller.coeffs
    coeffs = tuple(tuple(decimal(v) for v in c[:, j]) for j in range(c.shape[1]))
    offsets = tuple(decimal(v) for v in labeller.offsets)
    gaps = [_relative_gap(c[k, j], coeffs[j][k]) for j in range(c.shape[1])
            for k in range(c.shape[0]) if coeffs[j][k] != 0]
    offset_gap = np.array([float(abs(Fraction(float(v)) - exact)) * (1 + 4 * UNIT_ROUNDOFF)
                           for v, exact in zip(labeller.offsets, offsets, strict=True)])
    return coeffs, offsets, max(gaps, default=0.0), offset_gap


@dataclass(eq=False)
class ExactLabels:
    """The belief labels of `labeller` on the exact filter: float where the margin decides them,
    exact elsewhere. `exact_decisions` counts the (row, atom) labels decided exactly."""

    filter: ExactFilter
    labeller: Labeller
    exact_decisions: int = 0
    coeffs: tuple[tuple[Fraction, ...], ...] = field(init=False)    # [atom][level]
    offsets: tuple[Fraction, ...] = field(init=False)
    coeff_gap: float = field(init=False)
    offset_gap: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        constants = self.labeller.exact_constants
        if constants is None:
            constants = self.labeller.exact_constants = _labeller_constants(self.labeller)
        self.coeffs, self.offsets, self.coeff_gap, offset_gap = constants
        self.offset_gap = offset_gap.copy()

    def scoped(self) -> ExactLabels:
        """The same labels on a filter with words of its own (ExactFilter.scoped), which its one
        owner compacts."""
        return ExactLabels(filter=self.filter.scoped(), labeller=self.labeller)

    def margins(self, beliefs: np.ndarray, words: np.ndarray) -> np.ndarray:
        """[n, m]: the bound on |c·b - fl(c·b̂)| + |offset - fl(offset)| (module docstring)."""
        n = beliefs.shape[1]
        total = beliefs.sum(axis=1)
        g = gamma(n)
        spread = np.exp(self.filter.distance(words))
        low, high = total / (1 + g), total / (1 - g)
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = np.maximum(spread / low - 1.0, 1.0 - 1.0 / (spread * high))
        rho = np.where(total > 0, rho, np.inf)
        weight = np.abs(beliefs) @ np.abs(self.labeller.coeffs)
        relative = rho + g + self.coeff_gap * (1.0 + rho)
        return 2.0 * (relative[:, None] * weight + self.offset_gap[None, :])

    def truth(self, beliefs: np.ndarray, words: np.ndarray) -> np.ndarray:
        """bool [n, m] in `belief_columns` order: the labels of the exact filter's beliefs after
        `words`, whose float images are `beliefs`."""
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        words = np.asarray(words, dtype=np.int64)
        labeller = self.labeller
        if not labeller.belief_columns.size or beliefs.shape[0] == 0:
            return np.zeros((beliefs.shape[0], labeller.belief_columns.size), dtype=bool)
        value = atom_values(beliefs, labeller.coeffs)
        truth = value > labeller.offsets
        close = np.abs(value - labeller.offsets) <= self.margins(beliefs, words)
        for row, atom in zip(*np.nonzero(close), strict=True):
            exact = self.filter.belief(int(words[row]))
            coeffs = self.coeffs[atom]
            truth[row, atom] = sum((c * b for c, b in zip(coeffs, exact, strict=True) if c and b),
                                   Fraction(0)) > self.offsets[atom]
            self.exact_decisions += 1
        return truth

    def step(self, q: np.ndarray, x: np.ndarray, beliefs: np.ndarray, words: np.ndarray,
             trust: np.ndarray | None = None) -> np.ndarray:
        """int [n]: DFA states after reading positions (x, beliefs) from q, belief labels exact;
        trust_pomdp.BLOCK_ROWS rows at a time (a row's labels and step are its own: atom_values
        sums alike in a batch of any size, and a label near its threshold is decided exactly)."""
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        n, block = beliefs.shape[0], trust_pomdp.BLOCK_ROWS
        if n <= block:
            return self.labeller.step(q, x, beliefs, trust, belief_truth=self.truth(beliefs, words))
        q, x, words = (np.broadcast_to(np.asarray(a), (n,)) for a in (q, x, words))
        return np.concatenate([
            self.labeller.step(q[rows], x[rows], beliefs[rows], None if trust is None else trust[rows],
                               belief_truth=self.truth(beliefs[rows], words[rows]))
            for rows in row_blocks(n, block)])


def exact_filter(pomdp: TrustPOMDP, rule: BeliefRule = "bayes", like: ExactFilter | None = None
                 ) -> ExactFilter:
    """The exact filter of `pomdp` under `rule`, held by the model and shared with every other
    caller for it: building one converts the whole model to fractions, which costs far more than
    an episode's labels (its memoised beliefs are a pure function of the model). `like`: as in
    ExactFilter, for the first call."""
    found = pomdp.exact_filters.get(rule)
    if found is None:
        found = pomdp.exact_filters[rule] = ExactFilter(pomdp=pomdp, rule=rule, like=like)
    return found


def exact_labels(pomdp: TrustPOMDP, labeller: Labeller, rule: BeliefRule = "bayes") -> ExactLabels:
    return ExactLabels(filter=exact_filter(pomdp, rule), labeller=labeller)
