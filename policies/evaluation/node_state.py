"""What a node of the episode tree knows besides its road, route and probability: its node state.

The unfolding (policies/evaluation/unfolding.py) is the same whether the spec's DFA state is
observed or hidden; only the node state differs:

- `ObservedState`: the DFA state q is a function of the observations (specs without trust-state
  atoms). A node carries q, the AV's belief b (which drives decisions and belief labels) and the
  true posterior over trust (equal to b under the default rule); optionally the posterior of a
  true driver other than the AV's model and a second reading of the spec (`Observation.truth`,
  `Observation.reference`, docs/driver_types.md). Belief labels are those of the exact filter
  (policies/belief/exact_labels.py): a node carries the word of its AV belief's history, and rows
  merge only with rows of the same word (trust_state_filter.split_by_words).
- `HiddenState`: the spec tests the hidden trust, so q is hidden too; a node carries the exact
  joint law J(θ, q) of policies/belief/trust_state_filter.py besides the posterior and b.

Every array is vectorised over the frontier's rows; every method keeps the row subsets and the
order of operations of the loops it serves, so values are bit for bit those of each reading.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Protocol, Self

import numpy as np

from trustroute.policies.belief.av_step import AVStep
from trustroute.policies.belief.exact_labels import ExactLabels, exact_labels, symbol_code
from trustroute.policies.belief.trust_state_filter import JointFilter
from trustroute.policies.logic.compiled import CompiledSpec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP


class NodeState(Protocol):
    """Per-node state aligned with a frontier's rows."""

    @property
    def posterior(self) -> np.ndarray:
        """[n, n_trust] exact law of θ given the history (final trust reads it)."""

    @property
    def belief(self) -> np.ndarray:
        """[n, n_trust] the AV's belief (decisions and belief labels read it)."""

    def take(self, rows: np.ndarray | slice) -> Self: ...

    def masses(self, rows: np.ndarray | slice | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(accepted, rejected, live) probability of each row (of `rows`)."""

    def told(self) -> np.ndarray:
        """The DFA state a policy is told at each row."""

    def joint_row(self, row: int) -> np.ndarray | None:
        """J(θ, q) of a row for the policy's context; None when q is observed."""

    def decision_columns(self) -> tuple[np.ndarray, ...]:
        """[n, w] columns: two rows of one route and one DFA state told, bit for bit equal in
        these, are decided alike by a policy."""

    def observation_probability(self, road: np.ndarray, human_action: int, performance: int) -> np.ndarray:
        """P(observation) per row after driving `road` (one per row) and observing (h, e) there
        (the true posterior's: the filter's own, bit for bit)."""

    def children(self, road: np.ndarray, human_action: int, performance: int, p_obs: np.ndarray) -> Self:
        """The node state of the rows where (h, e) is possible (`p_obs`, their
        `observation_probability`, > 0) after driving `road` (one per row) and observing it there;
        its DFA state is the parent's until `stepped`."""

    def allocate(self, rows: int) -> Self:
        """A node state of `rows` rows like this one, its arrays' contents unset (`put` fills them)."""

    def put(self, at: slice, part: Self) -> None:
        """Write the rows of `part` into rows `at` of this one (one of `allocate`'s)."""

    def stepped(self, road: np.ndarray) -> Self:
        """The children of one level (the rows of `children` of every observation, `road` their
        roads) with their DFA states stepped on the position they reached."""

    @property
    def word(self) -> np.ndarray:
        """[n] the AV belief's word (policies/belief/exact_labels.py): rows merge only within one."""

    def merge_columns(self) -> np.ndarray:
        """[n, width] float columns: rows equal in these (and road, the policy's route memory and
        the word) have equal futures."""

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays (one that two fields share counted once)."""

    def compact(self) -> Self:
        """The same rows, their words renumbered by their labels' filter after it forgets the
        words no row holds (ExactFilter.compact: the unfolding's filter is its own)."""


def beliefs_at(posterior: np.ndarray, belief: np.ndarray, rows: np.ndarray | slice
               ) -> tuple[np.ndarray, np.ndarray]:
    """(posterior[rows], belief[rows]); one array for both where the AV's belief is the true
    posterior (the same object: the Bayes filter of the AV's own model), so a node carries one."""
    chosen = posterior[rows]
    return chosen, chosen if belief is posterior else belief[rows]


def unset_rows(array: np.ndarray, rows: int) -> np.ndarray:
    """An array of `rows` rows shaped and typed like `array`'s, its contents unset."""
    return np.empty((rows, *array.shape[1:]), dtype=array.dtype)


def allocated_beliefs(posterior: np.ndarray, belief: np.ndarray, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """(posterior, belief) arrays of `rows` rows, one array for both where they are one."""
    allocated = unset_rows(posterior, rows)
    return allocated, allocated if belief is posterior else unset_rows(belief, rows)


def put_beliefs(into, at: slice, part) -> None:
    """Write `part`'s posterior and belief into rows `at` of `into`'s (allocated_beliefs')."""
    if (into.belief is into.posterior) != (part.belief is part.posterior):
        raise ValueError("a part's belief and posterior are one array where those it is put into are not")
    into.posterior[at] = part.posterior
    if into.belief is not into.posterior:
        into.belief[at] = part.belief


def distinct_nbytes(*arrays: np.ndarray) -> int:
    """Bytes of `arrays`, each object counted once."""
    return sum(array.nbytes for array in {id(array): array for array in arrays}.values())


@dataclass(frozen=True, eq=False)
class Observation:
    """How the observed-DFA nodes move: the AV's model and filter, the true driver, the spec read."""

    pomdp: TrustPOMDP
    compiled: CompiledSpec
    belief_rule: BeliefRule
    truth: TrustPOMDP | None = None
    reference: tuple[TrustPOMDP, CompiledSpec] | None = None

    @property
    def true_pomdp(self) -> TrustPOMDP:
        return self.pomdp if self.truth is None else self.truth

    @cached_property
    def labels(self) -> ExactLabels:
        """The AV's belief labels, decided exactly where floats cannot decide them, on words of
        this unfolding's own (ObservedState.compact forgets those no history holds)."""
        return exact_labels(self.pomdp, self.compiled.labeller, self.belief_rule).scoped()

    @cached_property
    def av_step(self) -> AVStep:
        """The AV's step: its filter and its belief's word (policies/belief/av_step.py)."""
        return AVStep(self.pomdp, self.labels, self.belief_rule)


@dataclass(frozen=True, eq=False)
class ObservedState:
    """Rows of (q, AV belief, true posterior, the AV belief's word) and the reference reading
    (q_ref, its belief)."""

    model: Observation
    q: np.ndarray
    belief: np.ndarray
    posterior: np.ndarray
    q_ref: np.ndarray
    ref_belief: np.ndarray
    word: np.ndarray

    def take(self, rows: np.ndarray | slice) -> ObservedState:
        posterior, belief = beliefs_at(self.posterior, self.belief, rows)
        return replace(self, q=self.q[rows], belief=belief, posterior=posterior,
                       q_ref=self.q_ref[rows], ref_belief=self.ref_belief[rows], word=self.word[rows])

    def masses(self, rows: np.ndarray | slice | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q = self.q if rows is None else self.q[rows]
        accepted = self.model.compiled.accepting[q]
        rejected = self.model.compiled.rejecting[q] & ~accepted
        live = ~(accepted | rejected)
        return accepted.astype(float), rejected.astype(float), live.astype(float)

    def reference_accepting(self, rows: np.ndarray) -> np.ndarray | None:
        """Per row of `rows`: does the reference reading accept there (None: no reference)."""
        if self.model.reference is None:
            return None
        return self.model.reference[1].accepting[self.q_ref[rows]]

    def told(self) -> np.ndarray:
        return self.q

    def joint_row(self, row: int) -> None:
        return None

    def decision_columns(self) -> tuple[np.ndarray, ...]:
        return (self.belief,)      # q is the state told

    def observation_probability(self, road: np.ndarray, human_action: int, performance: int) -> np.ndarray:
        truth = self.model.true_pomdp
        return truth.observation_probability(self.posterior, truth.road_incident[road], human_action,
                                             performance)

    def children(self, road: np.ndarray, human_action: int, performance: int, p_obs: np.ndarray
                 ) -> ObservedState:
        model, h, e = self.model, human_action, performance
        new_posterior = model.true_pomdp.posterior(self.posterior, model.true_pomdp.road_incident[road], h, e,
                                                   rule="bayes")
        incident = model.pomdp.road_incident[road]
        if model.belief_rule == "bayes" and model.truth is None:
            # the AV's filter is the true one: its posterior is new_posterior (the rows of
            # probability 0 are left out below)
            new_av = new_posterior
            new_word = model.labels.filter.extend(self.word, symbol_code(incident, h, e))
        else:
            # an observation the AV deems impossible leaves its belief and word unchanged (AVStep)
            new_av, new_word, _ = model.av_step.belief_and_word(self.belief, self.word, incident, h, e)
        new_ref = self.ref_belief
        if model.reference is not None:
            ref_pomdp = model.reference[0]
            new_ref, _ = ref_pomdp.filter(new_ref, ref_pomdp.road_incident[road], h, e)
        possible = p_obs > 0
        posterior, belief = beliefs_at(new_posterior, new_av, possible)
        return replace(self, q=self.q[possible], belief=belief, posterior=posterior,
                       q_ref=self.q_ref[possible], ref_belief=new_ref[possible], word=new_word[possible])

    def allocate(self, rows: int) -> ObservedState:
        posterior, belief = allocated_beliefs(self.posterior, self.belief, rows)
        return replace(self, q=unset_rows(self.q, rows), belief=belief, posterior=posterior,
                       q_ref=unset_rows(self.q_ref, rows), ref_belief=unset_rows(self.ref_belief, rows),
                       word=unset_rows(self.word, rows))

    def put(self, at: slice, part: ObservedState) -> None:
        put_beliefs(self, at, part)
        self.q[at], self.q_ref[at], self.word[at] = part.q, part.q_ref, part.word
        self.ref_belief[at] = part.ref_belief

    def stepped(self, road: np.ndarray) -> ObservedState:
        """The DFA (and the reference's) stepped on the position (road, b)."""
        q = np.asarray(self.model.labels.step(self.q, road, self.belief, self.word), dtype=np.int64)
        q_ref = self.q_ref
        if self.model.reference is not None:
            q_ref = self.model.reference[1].step(q_ref, road, self.ref_belief)
        return replace(self, q=q, q_ref=q_ref)

    def merge_columns(self) -> np.ndarray:
        return np.concatenate([self.q[:, None].astype(float), self.belief, self.posterior,
                               self.q_ref[:, None].astype(float), self.ref_belief], axis=1)

    @property
    def nbytes(self) -> int:
        return distinct_nbytes(self.q, self.belief, self.posterior, self.q_ref, self.ref_belief, self.word)

    def compact(self) -> ObservedState:
        return replace(self, word=self.model.labels.filter.compact(self.word))


def observed_root(model: Observation) -> ObservedState:
    """The root: the AV's initial belief and DFA state at position 0, the true driver's prior."""
    belief = np.asarray(model.pomdp.initial_belief, dtype=float)[None, :].copy()
    posterior = (belief if model.truth is None     # one array while the AV's filter is the true one
                 else np.asarray(model.truth.initial_belief, dtype=float)[None, :].copy())
    if model.reference is not None:
        ref_belief = np.asarray(model.reference[0].initial_belief, dtype=float)[None, :].copy()
        q_ref = model.reference[1].initial_states(ref_belief)
    else:
        ref_belief, q_ref = np.zeros((1, 0)), np.zeros(1, dtype=np.int64)
    word = np.zeros(1, dtype=np.int64)
    q = np.asarray(model.labels.step(np.full(1, model.compiled.dfa.initial), np.full(1, model.compiled.start),
                                     belief, word), dtype=np.int64)
    return ObservedState(model=model, q=q, belief=belief, posterior=posterior, q_ref=q_ref,
                         ref_belief=ref_belief, word=word)


@dataclass(frozen=True, eq=False)
class HiddenState:
    """Rows of (J(θ, q), true posterior, AV belief, its word) under one joint filter and belief
    rule."""

    filter: JointFilter
    belief_rule: BeliefRule
    labels: ExactLabels     # the AV filter's, on words of this unfolding's own (`compact`)
    joint: np.ndarray
    posterior: np.ndarray
    belief: np.ndarray
    word: np.ndarray

    def take(self, rows: np.ndarray | slice) -> HiddenState:
        posterior, belief = beliefs_at(self.posterior, self.belief, rows)
        return replace(self, joint=self.joint[rows], posterior=posterior, belief=belief,
                       word=self.word[rows])

    def masses(self, rows: np.ndarray | slice | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.filter.masses(self.joint if rows is None else self.joint[rows])

    def told(self) -> np.ndarray:
        return self.filter.likeliest_q(self.joint)

    def joint_row(self, row: int) -> np.ndarray:
        return self.joint[row]

    def decision_columns(self) -> tuple[np.ndarray, ...]:
        return self.belief, self.joint.reshape(len(self.joint), -1)

    def observation_probability(self, road: np.ndarray, human_action: int, performance: int) -> np.ndarray:
        pomdp = self.filter.pomdp
        return pomdp.observation_probability(self.posterior, pomdp.road_incident[road], human_action,
                                             performance)

    def children(self, road: np.ndarray, human_action: int, performance: int, p_obs: np.ndarray
                 ) -> HiddenState:
        pomdp, h, e = self.filter.pomdp, human_action, performance
        incident = pomdp.road_incident[road]
        new_posterior = pomdp.posterior(self.posterior, incident, h, e, rule="bayes")
        new_av = (new_posterior if self.belief_rule == "bayes"
                  else pomdp.filter(self.belief, incident, h, e, rule=self.belief_rule)[0])
        possible = p_obs > 0
        labels = self.labels
        new_word = labels.filter.extend(self.word[possible], symbol_code(incident[possible], h, e))
        posterior, belief = beliefs_at(new_posterior, new_av, possible)
        new_joint = self.filter.update(self.joint[possible], posterior, belief, road[possible],
                                       (incident[possible], h, e), p_obs[possible], new_word, labels)
        return replace(self, joint=new_joint, posterior=posterior, belief=belief, word=new_word)

    def allocate(self, rows: int) -> HiddenState:
        posterior, belief = allocated_beliefs(self.posterior, self.belief, rows)
        return replace(self, joint=unset_rows(self.joint, rows), posterior=posterior, belief=belief,
                       word=unset_rows(self.word, rows))

    def put(self, at: slice, part: HiddenState) -> None:
        put_beliefs(self, at, part)
        self.joint[at], self.word[at] = part.joint, part.word

    def stepped(self, road: np.ndarray) -> HiddenState:
        return self      # J is stepped with the filter, in `children`

    def merge_columns(self) -> np.ndarray:
        """Columns of belief/trust_state_filter.distinct_nodes after the road: J, posterior, b."""
        return np.concatenate([self.joint.reshape(len(self.joint), -1), self.posterior, self.belief],
                              axis=1)

    @property
    def nbytes(self) -> int:
        return distinct_nbytes(self.joint, self.posterior, self.belief, self.word)

    def compact(self) -> HiddenState:
        return replace(self, word=self.labels.filter.compact(self.word))


def hidden_root(joint_filter: JointFilter, start: int, belief_rule: BeliefRule) -> HiddenState:
    """The root: θ0 ~ the AV's initial belief (the true posterior and b alike), q0 read at `start`."""
    belief = np.asarray(joint_filter.pomdp.initial_belief, dtype=float)[None, :].copy()
    return HiddenState(filter=joint_filter, belief_rule=belief_rule,
                       labels=joint_filter.labels(belief_rule).scoped(),
                       joint=joint_filter.initial(start, belief[0]), posterior=belief, belief=belief,
                       word=np.zeros(1, dtype=np.int64))
