"""Certified bounds rounded outward: the floating-point error of a synthesis' L and U, proven.

A value the search, its completions, the abstraction or `evaluate` computes is a float sum over
histories of products of float observation probabilities. Against the exact process (the model's
numbers as the decimals they print as; docs/synthesis.md, "Labels at thresholds") each history's
term carries a relative error at most γ_N, N = `history_units(...)`, so the computed value lies
within a factor (1 ± γ_N) of the exact quantity it stands for (docs/synthesis.md, "Rounding"
proves it). `widen` turns the computed [L, U] into one that holds exactly: L down by that factor,
U up, each rounded outward once more, clamped to [0, 1]. Zero stays zero, and an upper bound of
one stays one (a computed lower bound of one is moved down by its margin like any other).

The per-step units depend on the model: the relative gaps of its float likelihoods and update
matrices to the exact ones, and how far its exact transition rows sum from 1, each computed
exactly (`ModelRounding`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from fractions import Fraction

import numpy as np

from trustroute.policies.belief.exact_labels import decimal, exact_prior
from trustroute.policies.belief.problem import Problem
from trustroute.policies.evaluation.ledgers import Evaluation
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.labelling import UNIT_ROUNDOFF, gamma
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP

# Outcomes (h, e) of one road: the terms of one backup's sum, at most.
MAX_OUTCOMES = 4
# Units for the margin's own evaluation: 1 - γ_N and the product each round once, and the result
# is moved one more float outward (`widen`).
WIDEN_UNITS = 4


def _units(relative: float) -> int:
    """The smallest k with k·u >= `relative` (so γ_k >= relative); huge when it is infinite."""
    if not math.isfinite(relative):
        return 2 ** 40
    return math.ceil(relative / UNIT_ROUNDOFF)


def _relative(approximate: float, exact: Fraction) -> float:
    """|approximate - exact| / exact, rounded up (0 when both are 0, inf when only exact is)."""
    if exact == 0:
        return 0.0 if approximate == 0 else math.inf
    gap = abs(Fraction(float(approximate)) - exact) / abs(exact)
    return float(gap) * (1 + 4 * UNIT_ROUNDOFF)


@dataclass(frozen=True)
class ModelRounding:
    """A model's rounding constants, in units of u = 2**-53 (each the exact relative gap, rounded up).

    likelihood: float P(h, e | θ) against the exact decimals' products; matrix: the float update
    matrices against the exact ones; rows: how far an exact
    transition row sums from 1 (the model file allows 1e-9), which the exact process's probability
    b·ℓ and its update b W / (b W 1) then differ by; prior: the float prior against the exact one."""

    n: int
    likelihood: int
    matrix: int
    rows: int
    prior: int

    def step_units(self, rule: BeliefRule) -> int:
        """Units of one observation step of one history (docs/synthesis.md, "Rounding")."""
        n = self.n
        if rule == "bayes":
            # p̂ = b̂·ℓ̂ (n + ℓ), û = b̂ Ŵ (n + W), t̂ = Σ û (n - 1 more), one division, the float
            # belief's sum against 1 (n), the rows' sums, one backup sum of MAX_OUTCOMES terms
            return 5 * n + self.likelihood + 2 * self.matrix + self.rows + 1 + MAX_OUTCOMES
        # the authors' rule: b̂ drifts from the exact paper belief by one update's rounding per
        # step in Hilbert's metric (twice the one-step units), which each later probability carries
        return 2 * (2 * n + self.matrix + self.rows + 1) + n + self.likelihood + MAX_OUTCOMES

    def history_units(self, depth: int, rule: BeliefRule) -> int:
        """N with every history of at most `depth` observation steps within (1 ± γ_N) of exact."""
        depth = max(int(depth), 0)
        step = self.step_units(rule)
        if rule == "bayes":
            return self.prior + depth * step
        # the drift before step i is i - 1 steps' worth: Σ_i (i - 1) = depth (depth - 1) / 2
        drift = 2 * (2 * self.n + self.matrix + self.rows + 1)
        return self.prior + depth * step + drift * depth * max(depth - 1, 0) // 2


def model_rounding(pomdp: TrustPOMDP, rule: BeliefRule = "bayes") -> ModelRounding:
    """The rounding constants of `pomdp` under `rule` (ModelRounding), computed exactly, once per
    model and rule (held on the model: TrustPOMDP.roundings). The update matrices' gap follows
    from the likelihoods': a float matrix entry is fl(ℓ̂_k T̂_kl) (Bayes) or T̂_kl (the authors'
    rule), and T̂_kl is the float nearest its own decimal (within u)."""
    found = pomdp.roundings.get(rule)
    if found is None:
        found = pomdp.roundings[rule] = _model_rounding(pomdp, rule)
    return found


def _row_gap(row: list[float], decimals: dict[float, Fraction]) -> Fraction:
    """|Σ row - 1| exactly, each entry the decimal it prints as (kept in `decimals`, by float):
    summed in integers over the entries' common denominator."""
    entries = [decimals.get(v) or decimals.setdefault(v, decimal(v)) for v in row if v]
    denominator = math.lcm(*(entry.denominator for entry in entries))
    total = sum(entry.numerator * (denominator // entry.denominator) for entry in entries)
    return Fraction(abs(total - denominator), denominator)


def _model_rounding(pomdp: TrustPOMDP, rule: BeliefRule) -> ModelRounding:
    driver, n = pomdp.driver, pomdp.n_trust
    likelihood_gap, row_gap = 0.0, Fraction(0)
    decimals: dict[float, Fraction] = {}        # a model's rows hold few distinct numbers
    for i in range(len(driver.incident_types)):
        take = [decimal(t) for t in driver.takeover_probability[i].tolist()]
        fail = [decimal(f) for f in driver.failure_probability[i].tolist()]
        for h in (0, 1):
            for e in (0, 1):
                floats = pomdp.observation_likelihood[i, h, e].tolist()
                for k in range(n):
                    exact = (take[k] if h else 1 - take[k]) * (fail[k] if e else 1 - fail[k])
                    likelihood_gap = max(likelihood_gap, _relative(floats[k], exact))
                for row in driver.trust_transition[i, h, e].tolist():
                    row_gap = max(row_gap, _row_gap(row, decimals))
    prior = exact_prior(driver)
    prior_gap = max((_relative(f, b) for f, b in zip(np.asarray(pomdp.initial_belief).tolist(), prior,
                                                     strict=True)), default=0.0)
    # the float prior need not sum to 1: its sum's gap is at most n of its entries' gap, plus n
    # roundings of the sum the first probability makes of it
    likelihood = _units(likelihood_gap)
    return ModelRounding(n=n, likelihood=likelihood, matrix=likelihood + 2 if rule == "bayes" else 1,
                         rows=_units(float(row_gap) * (1 + 4 * UNIT_ROUNDOFF)),
                         prior=2 * _units(prior_gap) + n)


def joint_rounding(pomdp: TrustPOMDP, n_q: int, rule: BeliefRule = "bayes") -> ModelRounding:
    """The constants of the joint (θ, q) filter of trust-state specs: vectors of n_trust · n_q
    entries, the same model numbers."""
    return replace(model_rounding(pomdp, rule), n=pomdp.n_trust * max(n_q, 1))


def problem_rounding(problem: Problem, pomdp: TrustPOMDP | None = None) -> ModelRounding:
    """The constants of the unfolding that values a policy on `problem` (or on `pomdp` in its
    place): the joint (θ, q) filter's when the DFA state is hidden, the model's otherwise. Its
    probabilities are the true process's, a Bayes posterior whatever the AV's own rule."""
    return evaluation_rounding(pomdp or problem.pomdp, problem.spec, problem.dfa_hidden)


def evaluation_rounding(pomdp: TrustPOMDP, spec: Spec, dfa_hidden: bool) -> ModelRounding:
    """The constants of the unfolding that values a policy for `spec` with `pomdp` giving the
    probabilities: the joint (θ, q) filter's when the DFA state is hidden (`dfa_hidden`), the
    model's otherwise (Bayes: the true process's posterior, whatever the AV's own rule)."""
    if dfa_hidden:
        return joint_rounding(pomdp, compile_spec(spec, pomdp.town).dfa.n_states)
    return model_rounding(pomdp)


def certify(value: Evaluation, rounding: ModelRounding) -> Evaluation:
    """An evaluation's computed [lower, upper] rounded outward for its histories of at most
    `value.max_junctions` steps under the constants `rounding` (`evaluation_rounding`), so that it
    holds exactly: every evaluation reported to a user (`evaluate`, `baseline`, a study's
    expected values) is this one."""
    lower, upper = evaluation_widened(value.lower, value.upper, rounding, value.max_junctions)
    return replace(value, lower=lower, upper=upper)


def evaluation_widened(lower: float, upper: float, rounding: ModelRounding, depth: int
                       ) -> tuple[float, float]:
    """An evaluation's computed [lower, upper] rounded outward for its histories of at most `depth`
    steps under the constants `rounding`: its probabilities are the true driver's Bayes posterior
    whatever the AV's own rule, so the Bayes units apply."""
    return widen(lower, upper, relative_margin(rounding, depth, "bayes"))


def relative_margin(rounding: ModelRounding, depth: int, rule: BeliefRule) -> float:
    """γ_N for histories of at most `depth` steps (1 when N is beyond float64's reach)."""
    units = rounding.history_units(depth, rule) + WIDEN_UNITS
    return gamma(units) if units * UNIT_ROUNDOFF < 0.5 else 1.0


def rounded_down(values: np.ndarray | float, margin: float) -> np.ndarray:
    """values (1 - margin), evaluated in floats and moved one float down, clamped to [0, 1]; a
    value >= 0 computed as a sum of terms each within (1 ± γ_N) of exact, with margin >= γ_N, is
    then at most exact / (1 + γ_N) <= exact. Zero stays zero."""
    values = np.asarray(values, dtype=float)
    if margin >= 0.5:
        return np.zeros_like(values)
    low = np.nextafter(values * (1.0 - margin), -np.inf)
    return np.where(values > 0.0, np.clip(low, 0.0, 1.0), 0.0)


def rounded_up(values: np.ndarray | float, margin: float) -> np.ndarray:
    """values (1 + 2 margin) >= values / (1 - margin) for margin <= 1/2, evaluated in floats and moved
    one float up, clamped to [0, 1]: at least the exact value a computed one within (1 ± γ_N) of
    it stands for. Zero stays zero (a sum of such terms is 0 only when the exact one is)."""
    values = np.asarray(values, dtype=float)
    high = np.nextafter(values * (1.0 + 2.0 * min(margin, 0.5)), np.inf)
    return np.where(values > 0.0, np.clip(high, 0.0, 1.0), 0.0)


def widen(lower: float, upper: float, margin: float) -> tuple[float, float]:
    """[lower, upper] as computed, rounded outward by the relative `margin` (γ_N): `rounded_down`
    and `rounded_up`, clamped to [0, 1], so 0 and 1 stay as they are."""
    return float(rounded_down(lower, margin)), float(rounded_up(upper, margin))
