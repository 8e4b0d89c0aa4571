"""The trust POMDP of a town and a driver model, and its exact Bayes belief filter.

States are (x, θ): x a directed road of the town (observed), θ the human's trust (hidden).
An action at x is the next junction. After driving road x' the vehicle observes
o = (incident of x', human action h, AV performance e). See docs/model.md, "The model".
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

from trustroute.core.fields import OneOf, check_value
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel, check_covers_town

BeliefRule = Literal["bayes", "paper"]
BELIEF_RULES: tuple[BeliefRule, ...] = get_args(BeliefRule)
BELIEF_RULE_NAMES = OneOf(choices=BELIEF_RULES, noun="belief rule")   # as a config or a setting names one
ObservationRows = tuple[np.ndarray, np.ndarray, np.ndarray]   # incident, human action, performance per row


# Rows a vectorised step (a belief update, a label step) computes at a time, so that its temporaries
# (a belief update's [rows, θ, θ'] transition matrices: about 1.6 MB with 7 trust levels) stay
# small however many rows it is given (an evaluation's level has up to millions).
BLOCK_ROWS = 4096


def row_blocks(n: int, size: int) -> Iterator[slice]:
    """Slices of `size` rows (at least 1) covering rows 0 .. n - 1 in order."""
    step = max(size, 1)
    return (slice(begin, begin + step) for begin in range(0, n, step))


def checked_belief_rule(rule: str) -> BeliefRule:
    """`rule` as a BeliefRule, for a name read from outside (a config, a command line, an API
    keyword); an InputError naming --belief-rule when it names no rule."""
    return check_value(rule, BELIEF_RULE_NAMES, "--belief-rule", "")


@dataclass(frozen=True, eq=False)
class TrustPOMDP:
    """Arrays indexed by state index (town.states order) and driver-model incident index."""

    town: Town
    driver: DriverModel
    road_incident: np.ndarray = field(init=False)       # [n_states] incident index of each road
    successor_table: np.ndarray = field(init=False)     # [n_states, max_actions] state idx or -1
    action_junctions: tuple[tuple[str, ...], ...] = field(init=False)
    observation_likelihood: np.ndarray = field(init=False)  # [n_inc, 2(h), 2(e), n_trust]
    weighted_transition: np.ndarray = field(init=False)     # [n_inc, 2, 2, n_trust, n_trust]
    # observations whose probability is the same for every trust level (then exactly that constant)
    uniform_likelihood: np.ndarray = field(init=False)      # bool [n_inc, 2, 2]
    _preserving: dict = field(init=False, repr=False)       # rule -> bool [n_inc, 2, 2]
    # The model's exact filters (rule -> policies/belief/exact_labels.py's ExactFilter), built
    # there on first use and held here: trackers, evaluations and searches of one model share one.
    exact_filters: dict = field(default_factory=dict, init=False, repr=False)
    # The model's rounding constants (rule -> policies/synthesis/rounding.py's ModelRounding), computed
    # there on first use and held here: every synthesis and evaluation of one model reads them.
    roundings: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        town, driver = self.town, self.driver
        check_covers_town(driver, set(town.incidents.values()), town.source_path)
        road_incident = np.array([driver.incident_index(town.incident(s)) for s in town.states])
        actions = tuple(town.actions(s) for s in town.states)
        successors = town.successor_table
        takeover = driver.takeover_probability                    # [n_inc, θ]
        failure = driver.failure_probability
        p_h = np.stack([1 - takeover, takeover], axis=1)          # [n_inc, h, θ]
        p_e = np.stack([1 - failure, failure], axis=1)            # [n_inc, e, θ]
        likelihood = p_h[:, :, None, :] * p_e[:, None, :, :]      # [n_inc, h, e, θ]
        weighted = likelihood[..., :, None] * driver.trust_transition
        uniform = (likelihood == likelihood[..., :1]).all(axis=-1)
        preserving = {rule: _scaled_identity(matrices) for rule, matrices in
                      (("bayes", weighted), ("paper", driver.trust_transition))}
        for array in preserving.values():
            array.setflags(write=False)
        for name, value in (("road_incident", road_incident), ("successor_table", successors),
                            ("action_junctions", actions),
                            ("observation_likelihood", likelihood),
                            ("weighted_transition", weighted), ("uniform_likelihood", uniform),
                            ("_preserving", preserving)):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_states(self) -> int:
        return len(self.town.states)

    @property
    def n_trust(self) -> int:
        return self.driver.n_trust

    @property
    def initial_belief(self) -> np.ndarray:
        return self.driver.initial_belief

    def preserves_belief(self, rule: BeliefRule = "bayes") -> np.ndarray:
        """bool [n_inc, 2(h), 2(e)]: the update matrix of `rule` is c·I (c > 0), so the posterior
        is the belief itself (Bayes: T = I and a likelihood equal for every trust level)."""
        if rule not in self._preserving:
            raise ValueError(f"unknown belief rule {rule!r}; use 'bayes' or 'paper'")
        return self._preserving[rule]

    def observation_probability(self, beliefs: np.ndarray, incident: np.ndarray | int,
                                human_action: np.ndarray | int,
                                performance: np.ndarray | int = 0) -> np.ndarray:
        """P(h, e | b, inc) = Σθ b(θ) P(h | θ, inc) P(e | θ, inc), for each row of `beliefs`.

        An observation whose likelihood is the same constant c for every trust level has probability
        exactly c (its value for every belief in exact arithmetic; Σθ b(θ) c of a float belief can
        be c·(1 - 2e-16)), so a road where nothing can happen costs no probability mass."""
        beliefs = np.atleast_2d(beliefs)
        likelihood = _shaped(self.observation_likelihood[incident, human_action, performance], beliefs.shape)
        probability = np.einsum("nk,nk->n", beliefs, likelihood)
        uniform = _shaped(self.uniform_likelihood[incident, human_action, performance], probability.shape)
        if uniform.any():
            constant = likelihood[:, 0]
            # a zero belief row (a history of probability 0) keeps probability 0
            probability = np.where(uniform & beliefs.any(axis=1), constant, probability)
        return probability

    def belief_update(self, beliefs: np.ndarray, incident: np.ndarray | int,
                      human_action: np.ndarray | int, performance: np.ndarray | int = 0,
                      rule: BeliefRule = "bayes") -> tuple[np.ndarray, np.ndarray]:
        """Bayes filter, vectorised over rows: returns (posteriors, observation probabilities).

        b'(θ') ∝ Σθ b(θ) P(h|θ,inc) P(e|θ,inc) T[inc][h][e](θ,θ')   (docs/model.md, "Belief").
        rule="paper" is the authors' released update b' ∝ b·T[inc][h] (no likelihood weighting);
        the returned probabilities are the Bayes ones in both cases.
        An observation of probability 0 gives a zero row of probability 0 (never NaN).
        An observation whose update is c·I (`preserves_belief`, e.g. the default model's `none`)
        returns the belief unchanged, bit for bit: renormalising would move it by an ulp or so
        (the uniform prior sums to 1 - 2e-16), and repeated renormalisation does not settle
        (it can cycle), so the belief would drift along roads where nothing happens
        (docs/synthesis.md, "One filter").
        """
        beliefs, observation = _observation_rows(beliefs, incident, human_action, performance)
        return (_in_blocks(self._posterior_rows, beliefs, observation, rule, beliefs.shape),
                _in_blocks(self._probability_rows, beliefs, observation, rule, beliefs.shape[:1]))

    def posterior(self, beliefs: np.ndarray, incident: np.ndarray | int, human_action: np.ndarray | int,
                  performance: np.ndarray | int = 0, rule: BeliefRule = "bayes") -> np.ndarray:
        """`belief_update`'s posteriors alone, bit for bit: for a caller that holds the rows'
        observation probabilities already (`observation_probability` gives `belief_update`'s), so
        that each is computed once."""
        beliefs, observation = _observation_rows(beliefs, incident, human_action, performance)
        return _in_blocks(self._posterior_rows, beliefs, observation, rule, beliefs.shape)

    def _probability_rows(self, beliefs: np.ndarray, observation: ObservationRows,
                          rule: BeliefRule) -> np.ndarray:
        """`belief_update`'s observation probabilities of rows (Bayes' whatever the rule)."""
        return self.observation_probability(beliefs, *observation)

    def _posterior_rows(self, beliefs: np.ndarray, observation: ObservationRows,
                        rule: BeliefRule) -> np.ndarray:
        """`belief_update`'s posteriors of rows given an index per row for each part of the
        observation."""
        incident, human_action, performance = observation
        if rule == "bayes":
            matrices = self.weighted_transition[incident, human_action, performance]
        elif rule == "paper":
            matrices = self.driver.trust_transition[incident, human_action, performance]
        else:
            raise ValueError(f"unknown belief rule {rule!r}; use 'bayes' or 'paper'")
        unnormalised = np.einsum("nk,nkl->nl", beliefs, matrices)
        total = unnormalised.sum(axis=1, keepdims=True)
        posterior = np.divide(unnormalised, total, out=np.zeros_like(unnormalised),
                              where=total > 0)
        keep = self.preserves_belief(rule)[incident, human_action, performance]
        if keep.any():
            posterior[keep] = beliefs[keep]
        return posterior

    def filter(self, beliefs: np.ndarray, incident: np.ndarray | int, human_action: np.ndarray | int,
               performance: np.ndarray | int = 0,
               rule: BeliefRule = "bayes") -> tuple[np.ndarray, np.ndarray]:
        """The AV's filter step, vectorised over rows: (posteriors, possible). `belief_update`'s
        posterior where the observation is possible under this model; where it is not (a zero
        posterior: the model gives the observation probability 0, e.g. a driver unlike the AV's
        model), the prior is kept rather than a zero row. The one place of that rule: the episode
        tracker, the model engine, the exact evaluation, the gym env and the analysis all step the
        AV's belief through here."""
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        posterior = self.posterior(beliefs, incident, human_action, performance, rule=rule)
        possible = posterior.sum(axis=1) > 0
        if not possible.all():
            posterior[~possible] = beliefs[~possible]
        return posterior, possible

    def next_state(self, state: int, action_slot: int) -> int:
        return int(self.successor_table[state, action_slot])


# The filter runs once per history in the recursions (exact search, exact evaluation), where
# np.broadcast_to, a few microseconds a call, cost as much as the arithmetic: arrays already of
# their shape are used as they are, and scalar indices filled, which gives the same values.
def _shaped(array: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """`array` broadcast to `shape` (itself when it has that shape)."""
    return array if array.shape == shape else np.broadcast_to(array, shape)


def _index_rows(value: np.ndarray | int, n: int) -> np.ndarray:
    """An index per row: `value` broadcast to [n]."""
    value = np.asarray(value)
    return np.full(n, value) if value.ndim == 0 else _shaped(value, (n,))


def _observation_rows(beliefs: np.ndarray, incident: np.ndarray | int, human_action: np.ndarray | int,
                      performance: np.ndarray | int) -> tuple[np.ndarray, ObservationRows]:
    """Beliefs as float rows and an index per row for each part of the observation."""
    beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
    n = beliefs.shape[0]
    return beliefs, (_index_rows(incident, n), _index_rows(human_action, n), _index_rows(performance, n))


def _in_blocks(of_rows: Callable[[np.ndarray, ObservationRows, BeliefRule], np.ndarray], beliefs: np.ndarray,
               observation: ObservationRows, rule: BeliefRule, shape: tuple[int, ...]) -> np.ndarray:
    """of_rows(beliefs, observation, rule), of `shape`, BLOCK_ROWS rows at a time (one call for
    fewer). Each row's arithmetic is its own, in the same order whatever rows come with it: rows
    in blocks give the values of one call bit for bit."""
    n = beliefs.shape[0]
    if n <= BLOCK_ROWS:
        return of_rows(beliefs, observation, rule)
    out = np.empty(shape)
    for rows in row_blocks(n, BLOCK_ROWS):
        out[rows] = of_rows(beliefs[rows], (observation[0][rows], observation[1][rows], observation[2][rows]),
                            rule)
    return out


def _scaled_identity(matrices: np.ndarray) -> np.ndarray:
    """bool [...]: each trailing square matrix is exactly c·I with c > 0 (no tolerance: only then
    is the update the identity in exact arithmetic)."""
    n = matrices.shape[-1]
    diagonal = np.diagonal(matrices, axis1=-2, axis2=-1)
    off_diagonal = matrices * (1.0 - np.eye(n))
    return ((diagonal == diagonal[..., :1]).all(axis=-1) & (diagonal[..., 0] > 0)
            & (off_diagonal == 0).all(axis=(-2, -1)))


def build_pomdp(town: Town, driver: DriverModel) -> TrustPOMDP:
    return TrustPOMDP(town=town, driver=driver)
