"""The exact belief over (θ, q) when a spec tests the hidden trust (docs/trust_states.md).

Once a formula has trust-state atoms, the DFA state q after a position depends on the hidden
trust path, so it is hidden too. The exact filter keeps the joint law J(θ, q) of the current
trust and DFA state given the observations. After driving road x' and seeing o = (inc, h, e),

    J'(θ', q') ∝ Σ_{θ, q} J(θ, q) P(h | θ, inc) P(e | θ, inc) T[inc][h][e](θ, θ') [q' = δ(q, L(x', θ', b'))]

where b' is the AV's belief after the observation (belief atoms read it, decided exactly on its
history's word where floats cannot: policies/belief/exact_labels.py; under the default Bayes rule
it is the θ-marginal of J'). The normaliser is the observation probability of
policies/model/trust_pomdp.py, and the θ-marginal of J' is that module's posterior: it is taken
from there (so beliefs are bit for bit the product filter's), and J' carries the q part. Without trust-state
atoms q is a function of the observations: J' is the posterior times the indicator of the one
DFA state, computed exactly so (no sums over q at all).

Arrays are vectorised over rows n: J [n, n_trust, n_q].
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from trustroute.policies.belief.driver_types import base_trust_index
from trustroute.policies.belief.exact_labels import ExactLabels, exact_labels
from trustroute.policies.logic.dfa import DFA
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP, row_blocks


@dataclass(frozen=True, eq=False)
class JointFilter:
    """The (θ, q) filter of one spec on one trust POMDP."""

    pomdp: TrustPOMDP
    dfa: DFA
    labeller: Labeller

    @property
    def n_q(self) -> int:
        return int(self.dfa.n_states)

    @functools.cached_property
    def trust_index(self) -> np.ndarray:
        """The trust level index trust-state atoms read at each hidden index (a driver
        population's hidden index is (type, trust): policies/belief/driver_types.py)."""
        return base_trust_index(self.pomdp.driver)

    @functools.cached_property
    def _exact(self) -> dict[str, ExactLabels]:
        return {}

    def labels(self, rule: BeliefRule = "bayes") -> ExactLabels:
        """The belief labels of the AV's filter under `rule`, decided exactly where floats cannot
        (policies/belief/exact_labels.py); `update`'s words are this filter's."""
        found = self._exact.get(rule)
        if found is None:
            found = self._exact[rule] = exact_labels(self.pomdp, self.labeller, rule)
        return found

    def initial(self, start: int, belief: np.ndarray) -> np.ndarray:
        """J [1, n_trust, n_q] at position 0: θ0 ~ `belief`, q0 = δ(initial, L(start, b0, θ0))."""
        n_t = self.pomdp.n_trust
        belief = np.broadcast_to(np.asarray(belief, dtype=float), (n_t, n_t))
        thetas = np.arange(n_t)
        truth = self.labels().truth(belief, np.zeros(n_t, dtype=np.int64))
        q0 = self.labeller.step(np.full(n_t, self.dfa.initial), np.full(n_t, start), belief,
                                self.trust_index[thetas] if self.labeller.reads_trust else None,
                                belief_truth=truth)
        joint = np.zeros((1, n_t, self.n_q))
        joint[0, thetas, q0] = belief[0]
        return joint

    def update(self, joint: np.ndarray, posterior: np.ndarray, belief_av: np.ndarray, road: np.ndarray,
               observation: tuple[np.ndarray, int, int], probability: np.ndarray, words: np.ndarray,
               labels: ExactLabels) -> np.ndarray:
        """J' for each row after driving road x' (`road`) and observing `observation` = (incident
        [n], human action h, performance e): `posterior` [n, n_trust] and `probability` [n] are the
        θ filter's output for this observation (TrustPOMDP.belief_update), `belief_av` the AV's
        new belief and `words` its words in `labels` (the AV filter's exact labels, as `labels()`
        gives them). Rows of probability 0 give zero rows."""
        incident, human_action, performance = observation
        n, n_t, n_q = joint.shape
        truth = labels.truth(belief_av, words)
        if not self.labeller.reads_trust:
            # q is the same on every trust path: move its one DFA state, keep the posterior.
            q = np.argmax(joint.sum(axis=1), axis=1)
            q2 = self.labeller.step(q, road, belief_av, belief_truth=truth)
            out = np.zeros_like(joint)
            out[np.arange(n), :, q2] = posterior
            return out
        matrices = self.pomdp.weighted_transition[incident, human_action, performance]  # [n, θ, θ']
        predicted = np.einsum("ntq,ntu->nuq", joint, matrices)
        np.divide(predicted, probability[:, None, None], out=predicted,
                  where=probability[:, None, None] > 0)
        predicted[probability <= 0] = 0.0
        rows, thetas, qs = np.nonzero(predicted > 0)
        q2 = self.labeller.step(qs, road[rows], belief_av[rows], self.trust_index[thetas],
                                belief_truth=truth[rows])
        flat = (rows * n_t + thetas) * n_q + q2
        out = np.bincount(flat, weights=predicted[rows, thetas, qs], minlength=n * n_t * n_q)
        return out.astype(float, copy=False).reshape(n, n_t, n_q)   # (bincount of nothing is int)

    def q_marginal(self, joint: np.ndarray) -> np.ndarray:
        return joint.sum(axis=1)

    def likeliest_q(self, joint: np.ndarray) -> np.ndarray:
        """The DFA state a policy is told: the most probable one (lowest index on ties); the
        exact state when the spec has no trust-state atoms."""
        return np.argmax(self.q_marginal(joint), axis=1)

    def masses(self, joint: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(accepted, rejected, live) probability of each row."""
        marginal = self.q_marginal(joint)
        accepting = np.asarray(self.dfa.accepting, dtype=bool)
        rejecting = np.asarray(self.dfa.rejecting, dtype=bool) & ~accepting
        live = ~(accepting | rejecting)
        return marginal[:, accepting].sum(axis=1), marginal[:, rejecting].sum(axis=1), \
            marginal[:, live].sum(axis=1)


def _hash_multipliers(width: int) -> np.ndarray:
    """Fixed odd 64-bit multipliers, one per column (the same on every call and machine)."""
    return np.random.default_rng(20261201).integers(0, 2**63, size=width, dtype=np.uint64) * 2 + 1


HASH_CHUNK = 32_768   # rows hashed and checked at a time: the temporaries stay a few MB


def _row_chunks(n: int) -> Iterator[slice]:
    return row_blocks(n, HASH_CHUNK)


def distinct_rows(*blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(first, inverse) for the bit-identical rows of a float matrix [n, width], given as one or
    more blocks of its columns ([n, w_i] each, in order): first[k] is the first row of the k-th
    distinct row, inverse[i] the distinct row of row i. The rows are grouped by a 64-bit hash of
    their bits (sorting n integers instead of n byte strings) and the grouping is then checked bit
    for bit; should two different rows share a hash, the rows' bytes are sorted instead. Groups
    are numbered in hash order. The hash is a sum modulo 2**64 over the columns, so it is the
    same however the columns are split into blocks and the rows into chunks: the matrix is
    never put together (a search's level has hundreds of thousands of rows of 43 columns)."""
    blocks = tuple(np.ascontiguousarray(block, dtype=float) for block in blocks)
    n = blocks[0].shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    bits = [block.view(np.uint64) for block in blocks]
    ends = np.cumsum([block.shape[1] for block in blocks])
    multipliers = np.split(_hash_multipliers(int(ends[-1])), ends[:-1])
    hashes = np.zeros(n, dtype=np.uint64)
    for rows in _row_chunks(n):
        for block, multiplier in zip(bits, multipliers, strict=True):
            hashes[rows] += (block[rows] * multiplier[None, :]).sum(axis=1, dtype=np.uint64)
    _, first, inverse = np.unique(hashes, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    if not all(np.array_equal(block[rows], block[first[inverse[rows]]])
               for rows in _row_chunks(n) for block in bits):
        matrix = np.concatenate(blocks, axis=1)
        keys = matrix.view(np.dtype((np.void, matrix.dtype.itemsize * matrix.shape[1]))).ravel()
        _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return first, inverse.ravel()


def split_by_words(first: np.ndarray, inverse: np.ndarray, words: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(first, inverse) of `distinct_rows` with the rows whose word (exact_labels.ExactFilter)
    differs from their group's first row's moved to groups of their own, numbered after the others
    (so that, where no group mixes words, the grouping is distinct_rows' own, bit for bit)."""
    words = np.asarray(words, dtype=np.int64)
    clash = np.flatnonzero(words != words[first][inverse])
    if clash.size == 0:
        return first, inverse
    keys = np.stack([inverse[clash], words[clash]], axis=1)
    _, head, group = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.copy()
    inverse[clash] = first.size + group.ravel()
    return np.concatenate([first, clash[head]]), inverse


def distinct_nodes(x: np.ndarray, joint: np.ndarray, posterior: np.ndarray,
                   belief: np.ndarray, words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """distinct_rows of belief-tree nodes by (road, J, posterior, AV belief), split by the AV
    belief's word: nodes equal in all five have the same decisions and futures, so the searches
    and evaluations merge them."""
    first, inverse = distinct_rows(np.asarray(x)[:, None].astype(float), joint.reshape(len(x), -1),
                                   posterior, belief)
    return split_by_words(first, inverse, words)


def joint_filter(pomdp: TrustPOMDP, dfa: DFA, labeller: Labeller) -> JointFilter:
    return JointFilter(pomdp=pomdp, dfa=dfa, labeller=labeller)
