"""Random threshold cases and an exact-rational brute force, for the exact-label tests.

A case: a random small town (4-8 junctions), the default or a random driver model, a spec whose
belief atom's offset is a value the float filter reaches (c·b̂ at a belief along a random
observation sequence, a sum of prior entries, or k/7 under the uniform prior), exactly or one ulp
either side, and a horizon H = 2-8. `brute_force` is the optimum of the exact filter written here on
its own: the model's numbers as the decimals they print as, the prior normalised, beliefs as
integer-scaled vectors and observation probabilities as exact ratios, every belief label decided
exactly; values in floats. `exact_value` is the same in Fractions, of the optimum or of a policy,
under either belief rule (the authors' belief MDP included) and with another true driver (a type of
a population); exact_joint.py carries it over the joint law of trust and DFA state.

`small_case` and `small_spec` draw the tiny cases of the rounding tests (test_rounding*.py);
`sweep` marks all but a few of their seeds slow.

`reset_case` is a belief many histories reach on a threshold: two histories of different words
(a standstill and a takeover at an obstacle that resets trust) reach one belief, whose label floats
cannot decide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.synthesis.test_synthesis_random import random_junctions
from trustroute.networks.town import INCIDENT_TYPES, town_from_dict
from trustroute.participants.driver_model import DriverModel, driver_model_from_dict
from trustroute.policies.belief.exact_labels import decimal, exact_prior
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.labelling import atom_values
from trustroute.policies.logic.spec import Spec, spec_from_text
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP, build_pomdp
from trustroute.policies.routing.aware_table import BeliefTablePolicy
from trustroute.policies.synthesis.settings import SynthesisSettings

FORMULAS = ("F (v1 & !high)", "(!high) U a", "F (a & high)", "(!high) U (a & F b)", "F (a & F (b & high))")
KINDS = ("reached", "prior_sum", "sevenths")
BRUTE_FORCE_STATES = 60_000     # a case whose brute force would need more is drawn with a smaller H


def sweep(seeds: int, fast: tuple[int, ...]) -> list:
    """Seeds 0 .. seeds - 1 for a parametrized test, all but `fast` marked slow (the suite's budget
    takes a few of them, the slow run the sweep)."""
    return [seed if seed in fast else pytest.param(seed, marks=pytest.mark.slow) for seed in range(seeds)]


def random_town(rng: np.random.Generator, quiet: float, junctions: tuple[int, int] = (4, 8)):
    """`junctions` (at least, at most) junctions, a random tree plus a few chords; each road has an
    incident with probability 1 - quiet."""
    n = int(rng.integers(junctions[0], junctions[1] + 1))
    names = [chr(ord("A") + i) for i in range(n)]
    junctions = random_junctions(rng, names)
    roads = {tuple(sorted((names[i], names[int(rng.integers(i))]))) for i in range(1, n)}
    for _ in range(int(rng.integers(1, 3))):
        u, v = rng.choice(n, size=2, replace=False)
        roads.add(tuple(sorted((names[u], names[v]))))
    directed = [f"{u}-{v}" for a, b in sorted(roads) for u, v in ((a, b), (b, a))]
    eventful = [t for t in INCIDENT_TYPES if t != "none"]
    incidents = {road: ("none" if rng.random() < quiet else str(rng.choice(eventful))) for road in directed}
    return town_from_dict({"junctions": junctions, "roads": [list(r) for r in sorted(roads)],
                           "incidents": incidents}, "<random town>")


def small_case(seed: int, default_driver: DriverModel,
               eventful: bool = False) -> tuple[TrustPOMDP, Spec, int]:
    """A town of 3-5 junctions, the default or a random driver model (no AV failures), a spec with
    a belief atom (`small_spec`) and a horizon of 1-5. `eventful`: at most a quarter of the roads
    quiet, the atom's offset near its prior value and a horizon of 2-4, so that fewer optima are
    0 or 1."""
    rng = np.random.default_rng(seed)
    quiet = (0.0, 0.25) if eventful else (0.2, 0.6)
    town = random_town(rng, quiet=float(rng.uniform(*quiet)), junctions=(3, 5))
    model = default_driver if rng.random() < 0.5 else _without_failures(
        random_driver(rng, default_driver.incident_types))
    spec = small_spec(rng, town, prior=model.initial_belief if eventful else None)
    return build_pomdp(town, model), spec, int(rng.integers(2, 5) if eventful else rng.integers(1, 6))


def small_spec(rng: np.random.Generator, town, type_atom: str = "", prior: np.ndarray | None = None) -> Spec:
    """One of FORMULAS on random waypoints reachable from a random start, its belief atom `high` on
    random trust levels at an offset in [0.05, 0.6] (with `prior`: within 0.15 of its value there,
    in [0.01, 0.99]). With `type_atom` (the TOML of a type-belief atom `sure`), `high` reads
    `(high | sure)` in the formula (`!high`: `(!high & !sure)`)."""
    coeffs = np.zeros(7)
    coeffs[rng.choice(7, size=int(rng.integers(1, 7)), replace=False)] = 1.0
    if prior is None:
        offset = float(rng.uniform(0.05, 0.6))
    else:
        offset = float(np.clip(coeffs @ prior + rng.uniform(-0.15, 0.15), 0.01, 0.99))
    start = str(rng.choice(town.states))
    reachable = sorted(town.reachable_states(start) - {start}) or [start]

    def some(k: int) -> str:
        return str(sorted(rng.choice(reachable, size=min(k, len(reachable)), replace=False).tolist()))

    formula = FORMULAS[int(rng.integers(len(FORMULAS)))]
    if type_atom:
        formula = formula.replace("!high", "(!high & !sure)").replace(" high", " (high | sure)")
    text = (f'name = "rounding"\nstart = "{start}"\nformula = "{formula}"\n'
            f"[states]\na = {some(2)}\nb = {some(2)}\nv1 = {some(3)}\n".replace("'", '"')
            + f"[beliefs.high]\ncoeffs = {coeffs.tolist()}\noffset = {offset!r}\n" + type_atom)
    return spec_from_text(text, "<rounding spec>", town)


def _without_failures(model: DriverModel) -> DriverModel:
    """The random model with an AV that never fails (two symbols per incident: smaller trees)."""
    return DriverModel(trust_levels=model.trust_levels, incident_types=model.incident_types,
                       takeover_probability=model.takeover_probability,
                       failure_probability=np.zeros_like(model.failure_probability),
                       trust_transition=model.trust_transition, initial_belief=model.initial_belief,
                       trust_free_takeover_probability={}, source_path="<random>")


@dataclass(frozen=True)
class Case:
    seed: int
    kind: str
    nudge: int
    horizon: int
    pomdp: TrustPOMDP
    spec: Spec


def _reached_value(pomdp: TrustPOMDP, rng: np.random.Generator, coeffs: np.ndarray) -> float:
    """c·b̂ as the labeller computes it at a belief the float filter reaches along 0-3 random
    observations."""
    belief = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    n_inc = len(pomdp.driver.incident_types)
    for _ in range(int(rng.integers(0, 4))):
        incident, h = int(rng.integers(n_inc)), int(rng.integers(2))
        posterior, probability = pomdp.belief_update(belief, incident, h, 0)
        if probability[0] > 0:
            belief = posterior
    return float(atom_values(belief, coeffs[:, None])[0, 0])


def random_case(seed: int, default_driver) -> Case:
    rng = np.random.default_rng(seed)
    kind = KINDS[int(rng.integers(len(KINDS)))]
    town = random_town(rng, quiet=float(rng.uniform(0.3, 0.7)))
    if kind == "sevenths" or rng.random() < 0.5:
        model = default_driver           # uniform prior
    else:
        model = _without_failures(random_driver(rng, default_driver.incident_types))
    pomdp = build_pomdp(town, model)
    coeffs = np.zeros(7)
    coeffs[rng.choice(7, size=int(rng.integers(1, 7)), replace=False)] = 1.0
    if kind == "reached":
        offset = _reached_value(pomdp, rng, coeffs)
    elif kind == "prior_sum":
        offset = float(atom_values(np.asarray(pomdp.initial_belief)[None, :], coeffs[:, None])[0, 0])
    else:
        offset = int(coeffs.sum()) / 7
    nudge = int(rng.integers(-1, 2))
    if nudge:
        offset = float(np.nextafter(offset, np.inf * nudge))
    start = str(rng.choice(town.states))
    reachable = sorted(town.reachable_states(start) - {start}) or [start]
    a = sorted(rng.choice(reachable, size=min(2, len(reachable)), replace=False).tolist())
    b = sorted(rng.choice(reachable, size=min(2, len(reachable)), replace=False).tolist())
    v1 = sorted(rng.choice(reachable, size=min(3, len(reachable)), replace=False).tolist())
    formula = FORMULAS[int(rng.integers(len(FORMULAS)))]
    text = (f'name = "threshold"\nstart = "{start}"\nformula = "{formula}"\n'
            f"[states]\na = {a}\nb = {b}\nv1 = {v1}\n".replace("'", '"')
            + f"[beliefs.high]\ncoeffs = {coeffs.tolist()}\noffset = {offset!r}\n")
    spec = spec_from_text(text, "<threshold spec>", town)
    horizon = int(rng.integers(2, 9))
    while horizon > 2 and brute_force_states(pomdp, spec, horizon) > BRUTE_FORCE_STATES:
        horizon -= 1
    return Case(seed=seed, kind=kind, nudge=nudge, horizon=horizon, pomdp=pomdp, spec=spec)


def reset_case() -> Case:
    """A 5-junction line A-B-C-D with a detour B-E-C, 3 trust levels from the uniform prior; the
    obstacle on B-C is taken over with probability 1/2 at every level and either way resets the
    belief to (1/4, 1/4, 1/2), the other roads are quiet. The spec: reach C-D while P(level 3) >
    0.5 - 1 ulp, H = 3. Exactly 1/2 > that offset, so driving A-B, B-C, C-D satisfies it with
    probability 1; in floats the label at 1/2 lies within the rounding margin."""
    kinds = ["obstacle", "pedestrian", "truck", "none"]
    identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    reset = [[0.25, 0.25, 0.5]] * 3
    driver = driver_model_from_dict({
        "trust_levels": [1, 2, 3], "incident_types": kinds,
        "takeover_probability": {k: [0.0] * 3 if k == "none" else [0.5] * 3 for k in kinds},
        "trust_transition": {k: {"takeover": reset if k == "obstacle" else identity,
                                 "standstill": reset if k == "obstacle" else identity} for k in kinds}},
        "<reset driver>")
    roads = [["A", "B"], ["B", "C"], ["C", "D"], ["B", "E"], ["E", "C"]]
    town = town_from_dict({"junctions": {"A": [0, 0], "B": [300, 0], "C": [600, 0], "D": [900, 0],
                                         "E": [600, 300]},
                           "roads": roads,
                           "incidents": {f"{u}-{v}": "obstacle" if (u, v) == ("B", "C") else "none"
                                         for a, b in roads for u, v in ((a, b), (b, a))}},
                          "<reset town>")
    offset = float(np.nextafter(0.5, 0.0))
    spec = spec_from_text(f'name = "reset"\nstart = "A-B"\nformula = "F (a & high)"\n[states]\n'
                          f'a = ["C-D"]\n[beliefs.high]\ncoeffs = [0.0, 0.0, 1.0]\noffset = {offset!r}\n',
                          "<reset spec>", town)
    return Case(seed=-1, kind="reset", nudge=-1, horizon=3, pomdp=build_pomdp(town, driver), spec=spec)


def brute_force_states(pomdp: TrustPOMDP, spec: Spec, horizon: int) -> int:
    """An upper bound on the brute force's states: (road, word) pairs level by level (a word
    only grows on a road with an incident whose update is not the identity)."""
    town = pomdp.town
    preserving = pomdp.preserves_belief()
    changing = [not preserving[pomdp.road_incident[x], 0, 0] for x in range(len(town.states))]
    outcomes = 4 if pomdp.driver.depends_on_performance else 2
    counts = {town.state_index(spec.start): 1}
    total = 1
    for _ in range(horizon):
        nxt: dict[int, int] = {}
        for x, count in counts.items():
            for road in town.successors(town.states[x]):
                y = town.state_index(road)
                nxt[y] = nxt.get(y, 0) + count * (outcomes if changing[y] else 1)
        counts = nxt
        total += sum(counts.values())
        if total > 10 * BRUTE_FORCE_STATES:
            break
    return total


def _scaled(values: list[Fraction]) -> tuple[list[int], int]:
    """Integers and one denominator: values[i] = integers[i] / denominator (each value's
    denominator divides it: integer products, no Fraction arithmetic)."""
    denominator = math.lcm(*(v.denominator for v in values))
    return [v.numerator * (denominator // v.denominator) for v in values], denominator


def brute_force(pomdp: TrustPOMDP, spec: Spec, horizon: int) -> float:
    """max over policies of P(spec accepted within `horizon` junctions) on the exact filter, in
    floats (`exact_value`'s sums in floats: quicker on the larger threshold cases)."""
    return float(exact_value(pomdp, spec, horizon, number=float))


@dataclass(frozen=True)
class _ExactFilter:
    """One model's exact filter under one rule, in integers: per symbol (i, h, e) the likelihood
    (integer-scaled decimals and their scale) and the update matrix (Bayes: diag(ℓ) T, the
    authors' rule: T alone; integer-scaled, so images are beliefs up to a positive scale); the
    prior as integers. A belief is one integer vector per ray (divided by the gcd of its entries)."""

    n: int
    likelihood: dict
    update: dict
    prior: tuple[int, ...]

    @classmethod
    def of(cls, pomdp: TrustPOMDP, rule: BeliefRule) -> _ExactFilter:
        """The filter of `pomdp`'s model, built once per model and rule in a process: the
        rounding tests value each random model several times (its optimum, a policy, each type
        as the true driver), and building it is most of an exact value's time."""
        driver = pomdp.driver
        prior = exact_prior(driver)
        key = (rule, prior, driver.trust_transition.shape, driver.takeover_probability.tobytes(),
               driver.failure_probability.tobytes(), driver.trust_transition.tobytes())
        if key not in _FILTERS:
            _FILTERS[key] = cls._build(pomdp, rule, prior)
        return _FILTERS[key]

    @classmethod
    def _build(cls, pomdp: TrustPOMDP, rule: BeliefRule, prior: tuple[Fraction, ...]) -> _ExactFilter:
        driver, n = pomdp.driver, pomdp.n_trust
        likelihood, update = {}, {}
        # a model's numbers repeat (a type-lifted model's matrices are mostly zeros): each
        # distinct float is read as its decimal once, and a zero's products are zero
        decimals: dict[float, Fraction] = {0.0: Fraction(0)}

        def exact(value: float) -> Fraction:
            found = decimals.get(value)
            if found is None:
                found = decimals[value] = decimal(value)
            return found

        for i in range(len(driver.incident_types)):
            take = [exact(t) for t in driver.takeover_probability[i].tolist()]
            fail = [exact(f) for f in driver.failure_probability[i].tolist()]
            for h, e in ((0, 0), (0, 1), (1, 0), (1, 1)):
                like = [(take[k] if h else 1 - take[k]) * (fail[k] if e else 1 - fail[k]) for k in range(n)]
                likelihood[i, h, e] = _scaled(like)
                weight = like if rule == "bayes" else [Fraction(1)] * n
                rows = driver.trust_transition[i, h, e].tolist()
                flat, _ = _scaled([weight[k] * exact(value) if value else exact(value)
                                   for k in range(n) for value in rows[k]])
                update[i, h, e] = [flat[k * n:(k + 1) * n] for k in range(n)]
        return cls(n=n, likelihood=likelihood, update=update, prior=tuple(_scaled(list(prior))[0]))

    def probability(self, belief: tuple[int, ...], symbol: tuple[int, int, int]) -> Fraction:
        """P(symbol | belief), exactly."""
        like, scale = self.likelihood[symbol]
        return Fraction(sum(b * w for b, w in zip(belief, like, strict=True)), sum(belief) * scale)

    def update_belief(self, belief: tuple[int, ...], symbol: tuple[int, int, int]) -> tuple[int, ...]:
        """The posterior's ray; the belief itself where the symbol is impossible under it (the
        AV's filter keeps its belief then: TrustPOMDP.filter)."""
        matrix = self.update[symbol]
        image = [sum(belief[k] * matrix[k][m] for k in range(self.n) if belief[k]) for m in range(self.n)]
        common = math.gcd(*image)
        return belief if common == 0 else tuple(v // common for v in image)


_FILTERS: dict[tuple, _ExactFilter] = {}   # _ExactFilter.of's, by the model's numbers and the rule


class ExactLabelling:
    """The spec's atoms at a position, belief atoms c·b > offset compared in integers on an exact
    belief (integer-scaled decimals), road and trust-state atoms as the labeller reads them."""

    def __init__(self, labeller, n_hidden: int) -> None:
        self.labeller = labeller
        self.atoms = [(_scaled([decimal(c) for c in labeller.coeffs[:, j]]), decimal(offset))
                      for j, offset in enumerate(labeller.offsets)]
        self.n_hidden = n_hidden

    def valuations(self, x: int, belief: tuple[int, ...], trust: np.ndarray | None = None) -> np.ndarray:
        """bool [rows, atoms]: one row, or one per trust level index of `trust`."""
        rows = 1 if trust is None else len(trust)
        valuation = self.labeller.valuations(np.full(rows, x), np.zeros((rows, self.n_hidden)), trust)
        mass = sum(belief)
        for j, column in enumerate(self.labeller.belief_columns.tolist()):
            (coeffs, scale), offset = self.atoms[j]
            value = sum(c * b for c, b in zip(coeffs, belief, strict=True))
            valuation[:, column] = value * offset.denominator > offset.numerator * mass * scale
        return valuation


def _outcomes(driver: DriverModel) -> list[tuple[int, int]]:
    return [(h, e) for h in (0, 1) for e in ((0, 1) if driver.depends_on_performance else (0,))]


def exact_value(pomdp: TrustPOMDP, spec: Spec, horizon: int, policy: BeliefTablePolicy | None = None,
                number: type = Fraction, rule: BeliefRule = "bayes",
                truth: TrustPOMDP | None = None) -> Fraction:
    """max over policies (or the value of `policy`, acting on the vehicle's float filter) of
    P(spec accepted within `horizon` junctions) on the exact filter, exactly (`number` Fraction).

    The AV's belief runs `pomdp`'s exact filter under `rule`; the spec's belief labels read it.
    Observation probabilities are those of `truth`'s exact Bayes posterior from its own prior (the
    driver who drives: a type of a population, or the model itself under the authors' rule), or,
    without `truth`, of the AV's belief itself: under Bayes the real process, under the authors'
    rule the authors' belief MDP (the paper-rule belief gives the probabilities).

    Beliefs are integer vectors (the exact belief times a positive scale, divided by the gcd of
    their entries: one representative per belief), updated by the integer-scaled decimal matrices;
    a label c·b > offset is compared in integers; probabilities are exact ratios. A policy reads
    the float belief of TrustPOMDP.filter under `rule` along the same history, and the DFA state of
    the exact labels, as the vehicle does."""
    town = pomdp.town
    compiled = compile_spec(spec, town)
    labels = ExactLabelling(compiled.labeller, pomdp.n_trust)
    outcomes = _outcomes(pomdp.driver)
    av = _ExactFilter.of(pomdp, rule)
    true = None if truth is None else _ExactFilter.of(truth, "bayes")
    successors = [[town.state_index(s) for s in town.successors(road)] for road in town.states]

    def step(q: int, x: int, belief: tuple[int, ...]) -> int:
        return int(compiled.dfa.step_many(np.array([q]), labels.valuations(x, belief))[0])

    memo: dict = {}

    def moves(t: int, x: int, q: int, route: tuple[str, ...], float_belief: np.ndarray) -> list[int]:
        if policy is None:
            return successors[x]
        p = policy.task.projected_state(route)
        slot = int(policy.exact_action_slots(np.array([t]), np.array([x]), np.array([q]), np.array([p]),
                                             float_belief[None, :])[0])
        return [town.state_index(town.successors(town.states[x])[slot])]

    def value(t: int, x: int, q: int, belief: tuple[int, ...], law: tuple[int, ...] | None,
              route: tuple[str, ...], float_belief: np.ndarray):
        if compiled.accepting[q]:
            return number(1)
        if compiled.rejecting[q] or t == horizon:
            return number(0)
        key = (t, x, q, belief, law) if policy is None else (t, x, q, belief, law, route,
                                                             float_belief.tobytes())
        if key in memo:
            return memo[key]
        best = number(0)
        for x2 in moves(t, x, q, route, float_belief):
            i = int(pomdp.road_incident[x2])
            total = number(0)
            for h, e in outcomes:
                probability = (av.probability(belief, (i, h, e)) if true is None or law is None
                               else true.probability(law, (i, h, e)))
                if probability == 0:
                    continue
                posterior = av.update_belief(belief, (i, h, e))
                follow = (float_belief if policy is None
                          else pomdp.filter(float_belief[None, :], i, h, e, rule=rule)[0][0])
                total += number(probability) * value(
                    t + 1, x2, step(q, x2, posterior), posterior,
                    None if true is None or law is None else true.update_belief(law, (i, h, e)),
                    (*route, town.states[x2]), follow)
            best = max(best, total)
        memo[key] = best
        return best

    start = town.state_index(spec.start)
    return value(0, start, step(compiled.dfa.initial, start, av.prior), av.prior,
                 None if true is None else true.prior, (spec.start,),
                 np.asarray(pomdp.initial_belief, dtype=float))


@dataclass(frozen=True)
class Outcome:
    """One case's synthesis [lower, upper], the brute force's optimum and `evaluate`'s value of
    the returned policy."""

    case: Case
    lower: float
    upper: float
    optimum: float
    evaluated: float

    def reaches(self, tau: float) -> bool:
        return self.upper - self.lower <= tau

    def sound(self, tolerance: float) -> bool:
        return self.lower - tolerance <= self.optimum <= self.upper + tolerance

    def policy_worth_lower(self, tolerance: float) -> bool:
        return self.evaluated >= self.lower - tolerance


def run_case(case: Case, tau: float = 1e-3, time_limit: float = 20.0) -> Outcome:
    from trustroute.policies.evaluation.plain import evaluate
    from trustroute.policies.synthesis.belief_synthesis import synthesize

    result = synthesize(case.pomdp, case.spec,
                        SynthesisSettings(tau=tau, horizon=case.horizon, time_limit=time_limit))
    online = evaluate(case.pomdp, case.spec, result.policy,
                      EvaluationSettings(fallback_after=None, max_junctions=case.horizon))
    return Outcome(case=case, lower=result.lower, upper=result.upper,
                   optimum=brute_force(case.pomdp, case.spec, case.horizon), evaluated=online.lower)
