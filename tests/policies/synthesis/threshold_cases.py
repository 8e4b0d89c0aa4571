"""Random threshold cases and an exact-rational brute force, for the exact-label tests.

A case: a random small town (4-8 junctions), the default or a random driver model, a spec whose
belief atom's offset is a value the float filter reaches (c·b̂ at a belief along a random
observation sequence, a sum of prior entries, or k/7 under the uniform prior), exactly or one ulp
either side, and a horizon H = 2-8. `brute_force` is the optimum of the exact filter written here on
its own: the model's numbers as the decimals they print as, the prior normalised, beliefs as
integer-scaled vectors and observation probabilities as exact ratios, every belief label decided
exactly; values in floats.

`reset_case` is a belief many histories reach on a threshold: two histories of different words
(a standstill and a takeover at an obstacle that resets trust) reach one belief, whose label floats
cannot decide.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.synthesis.test_synthesis_random import random_junctions
from trustroute.networks.town import INCIDENT_TYPES, town_from_dict
from trustroute.participants.driver_model import DriverModel, driver_model_from_dict
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.labelling import atom_values
from trustroute.policies.logic.spec import Spec, spec_from_text
from trustroute.policies.model.trust_pomdp import TrustPOMDP, build_pomdp
from trustroute.policies.routing.aware_table import BeliefTablePolicy
from trustroute.policies.synthesis.settings import SynthesisSettings

FORMULAS = ("F (v1 & !high)", "(!high) U a", "F (a & high)", "(!high) U (a & F b)", "F (a & F (b & high))")
KINDS = ("reached", "prior_sum", "sevenths")
BRUTE_FORCE_STATES = 60_000     # a case whose brute force would need more is drawn with a smaller H


def _decimal(value: float) -> Fraction:
    return Fraction(repr(float(value)))


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
    """Integers and one denominator: values[i] = integers[i] / denominator."""
    denominator = math.lcm(*(v.denominator for v in values))
    return [int(v * denominator) for v in values], denominator


def brute_force(pomdp: TrustPOMDP, spec: Spec, horizon: int) -> float:
    """max over policies of P(spec accepted within `horizon` junctions) on the exact filter, in
    floats (`exact_value`'s sums in floats: quicker on the larger threshold cases)."""
    return float(exact_value(pomdp, spec, horizon, number=float))


def exact_value(pomdp: TrustPOMDP, spec: Spec, horizon: int, policy: BeliefTablePolicy | None = None,
                number: type = Fraction) -> Fraction:
    """max over policies (or the value of `policy`, acting on the vehicle's float filter) of
    P(spec accepted within `horizon` junctions) on the exact filter, exactly (`number` Fraction).

    Beliefs are integer vectors (the exact belief times a positive scale, divided by the gcd of
    their entries: one representative per belief), updated by the integer-scaled decimal matrices;
    a label c·b > offset is compared in integers; probabilities are exact ratios. A policy reads
    the float belief of TrustPOMDP.belief_update along the same history, and the DFA state of the
    exact labels, as the vehicle does."""
    driver, town = pomdp.driver, pomdp.town
    n = pomdp.n_trust
    compiled = compile_spec(spec, town)
    labeller, dfa = compiled.labeller, compiled.dfa
    atoms = [(_scaled([_decimal(c) for c in labeller.coeffs[:, j]]), _decimal(offset))
             for j, offset in enumerate(labeller.offsets)]
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if driver.depends_on_performance else (0,))]
    likelihood, update = {}, {}
    for i in range(len(driver.incident_types)):
        for h, e in outcomes:
            take = [_decimal(t) for t in driver.takeover_probability[i]]
            fail = [_decimal(f) for f in driver.failure_probability[i]]
            like = [(take[k] if h else 1 - take[k]) * (fail[k] if e else 1 - fail[k]) for k in range(n)]
            likelihood[i, h, e] = _scaled(like)
            flat, _ = _scaled([like[k] * _decimal(driver.trust_transition[i, h, e, k, m])
                               for k in range(n) for m in range(n)])
            update[i, h, e] = [flat[k * n:(k + 1) * n] for k in range(n)]
    prior, _ = _scaled([_decimal(b) for b in driver.initial_belief])
    successors = [[town.state_index(s) for s in town.successors(road)] for road in town.states]
    dummy = np.zeros((1, n))

    def step(q: int, x: int, belief: tuple[int, ...]) -> int:
        valuation = labeller.valuations(np.array([x]), dummy)
        mass = sum(belief)
        for j, column in enumerate(labeller.belief_columns.tolist()):
            (coeffs, scale), offset = atoms[j]
            value = sum(c * b for c, b in zip(coeffs, belief, strict=True))
            valuation[0, column] = value * offset.denominator > offset.numerator * mass * scale
        return int(dfa.step_many(np.array([q]), valuation)[0])

    memo: dict = {}

    def moves(t: int, x: int, q: int, route: tuple[str, ...], float_belief: np.ndarray) -> list[int]:
        if policy is None:
            return successors[x]
        p = policy.task.projected_state(route)
        slot = int(policy.exact_action_slots(np.array([t]), np.array([x]), np.array([q]), np.array([p]),
                                             float_belief[None, :])[0])
        return [town.state_index(town.successors(town.states[x])[slot])]

    def value(t: int, x: int, q: int, belief: tuple[int, ...], route: tuple[str, ...],
              float_belief: np.ndarray):
        if compiled.accepting[q]:
            return number(1)
        if compiled.rejecting[q] or t == horizon:
            return number(0)
        key = (t, x, q, belief) if policy is None else (t, x, q, belief, route, float_belief.tobytes())
        if key in memo:
            return memo[key]
        best = number(0)
        mass = sum(belief)
        for x2 in moves(t, x, q, route, float_belief):
            i = int(pomdp.road_incident[x2])
            total = number(0)
            for h, e in outcomes:
                like, scale = likelihood[i, h, e]
                weight = sum(b * w for b, w in zip(belief, like, strict=True))
                if weight == 0:
                    continue
                matrix = update[i, h, e]
                image = [sum(belief[k] * matrix[k][m] for k in range(n) if belief[k]) for m in range(n)]
                common = math.gcd(*image)
                posterior = tuple(v // common for v in image)
                probability = number(Fraction(weight, mass * scale))
                follow = (float_belief if policy is None
                          else pomdp.belief_update(float_belief[None, :], i, h, e)[0][0])
                total += probability * value(t + 1, x2, step(q, x2, posterior), posterior,
                                             (*route, town.states[x2]), follow)
            best = max(best, total)
        memo[key] = best
        return best

    start = town.state_index(spec.start)
    root = tuple(prior)
    return value(0, start, step(dfa.initial, start, root), root, (spec.start,),
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
