"""A simple belief-lookahead controller against the population synthesis on the paper's town with
the three-type example population (docs/driver_types.md, "Limits"): phi1 and phi2, the AV on the
exact lifted (type, trust) filter.

The controller (`LookaheadPolicy`) is a depth-limited expectimax on the AV's exact belief: at each
junction it tries every move and every observation of the next DEPTH roads, steps the DFA on the
posterior's labels, and values a history that ends there by 1 when the DFA accepts, 0 when
acceptance is more junctions away than are left, and otherwise by a heuristic of its belief that
trust is high (P(trust >= 6) and whether `hightrust` holds), discounted by the junctions still
needed. Within DEPTH junctions of the horizon it is the exact optimum. Its values are exact (the
project's evaluator, per type, certified [lower, upper]); the synthesis' are converged
(`tau` 1e-6) at the small horizons, where they are the optimum to within 1e-12.

Each row: the spec, the horizon, what was run (`optimum`: the Bayes synthesis; `full_lookahead`:
the controller looking ahead over every junction, which is the optimum, at FULL_HORIZON, where the
synthesis stops short of it; `lookahead`: the controller at DEPTH), the mixture's and every type's
certified [lower, upper] and the seconds.
"""

from __future__ import annotations

import time

import numpy as np

from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

DEPTH = 8
POPULATION = "driver_population_three_types"
SPECS = ("phi1", "phi2")
SMALL_HORIZONS = (8, 10, 12)   # where the synthesis converges within a minute
FULL_HORIZON = 14              # where a lookahead over every junction (the optimum) is still affordable
HORIZON = 20
HIGH_TRUST = "hightrust"
# the leaf heuristic: P(trust >= 6) counts half, the atom's truth half; each junction still
# needed for acceptance discounts it by DISCOUNT, and having no junction to spare halves it
DISCOUNT = 0.95
MEMO_SIZE = 2_000_000
TIE = 1e-12


class LookaheadPolicy(RoutingPolicy):
    """Depth-limited expectimax on the AV's exact belief (module docstring)."""

    name = "lookahead"

    def __init__(self, pomdp, spec, horizon: int, depth: int = DEPTH) -> None:
        from trustroute.policies.logic.compiled import compile_spec
        from trustroute.policies.routing.free import free_completion

        self.pomdp, self.horizon, self.depth = pomdp, horizon, depth
        compiled = compile_spec(spec, pomdp.town)
        names, self.next_q = compiled.label_table()
        self.coeffs = np.array([spec.belief_atoms[n].coeffs for n in names])
        self.offsets = np.array([spec.belief_atoms[n].offset for n in names])
        self.high = np.asarray(spec.belief_atoms[HIGH_TRUST].coeffs, dtype=float)
        self.high_offset = float(spec.belief_atoms[HIGH_TRUST].offset)
        self.accepting = compiled.accepting
        self.distance = free_completion(pomdp.town, spec).distance   # junctions, any labels
        likelihood = pomdp.observation_likelihood
        self.observations = [[(h, e) for h in range(2) for e in range(2) if likelihood[i, h, e].max() > 0]
                             for i in range(likelihood.shape[0])]
        self.memo: dict = {}

    def leaf(self, x: int, q: int, belief: np.ndarray, left: int) -> float:
        needed = int(self.distance[x, q])
        high = float(self.high @ belief)
        spare = 1.0 - 0.5 ** (left - needed + 1)
        return DISCOUNT ** needed * spare * 0.5 * (high + float(high > self.high_offset))

    def move_value(self, q: int, belief: np.ndarray, y: int, left: int, depth: int) -> float:
        """Expected value of driving onto road y: over its observations, the posterior's."""
        incident = int(self.pomdp.road_incident[y])
        total = 0.0
        for h, e in self.observations[incident]:
            unnormalised = belief @ self.pomdp.weighted_transition[incident, h, e]
            probability = float(unnormalised.sum())
            if probability > 0:
                posterior = unnormalised / probability
                bits = sum(1 << j for j, v in enumerate(self.coeffs @ posterior > self.offsets) if v)
                total += probability * self.value(y, int(self.next_q[q, y, bits]), posterior, left - 1,
                                                  depth - 1)[0]
        return total

    def value(self, x: int, q: int, belief: np.ndarray, left: int, depth: int) -> tuple[float, int]:
        """(value, best move's slot) of a history at road x, DFA state q, `left` junctions left."""
        if self.accepting[q]:
            return 1.0, 0
        if self.distance[x, q] > left:
            return 0.0, 0
        if depth == 0:
            return self.leaf(x, q, belief, left), 0
        key = (x, q, left, depth, belief.tobytes())
        if key not in self.memo:
            if len(self.memo) >= MEMO_SIZE:
                self.memo.clear()
            best = (-1.0, 0)
            for slot, y in enumerate(self.pomdp.successor_table[x]):
                value = self.move_value(q, belief, int(y), left, depth) if y >= 0 else -1.0
                if value > best[0] + TIE:   # the first of moves within TIE of each other
                    best = (value, slot)
            self.memo[key] = best
        return self.memo[key]

    def next_junction(self, context: DecisionContext) -> str:
        town = self.pomdp.town
        _, slot = self.value(town.state_index(context.road), context.dfa_state,
                             np.asarray(context.belief, dtype=float),
                             self.horizon - context.junctions_driven, self.depth)
        return town.actions(context.road)[slot]


def row(spec_name: str, horizon: int, what: str, values, weights: np.ndarray, seconds: float) -> dict:
    from trustroute.policies.synthesis.population import mixture_lower, mixture_upper, worst_type

    return {"name": f"{spec_name}_h{horizon}_{what}", "spec": spec_name, "horizon": horizon,
            "policy": what, "bayes": [mixture_lower(weights, values), mixture_upper(weights, values)],
            "worst_type": worst_type(values),
            "types": {v.name: [v.lower, v.upper] for v in values}, "seconds": seconds}


def run() -> list[dict]:
    import trustroute
    from trustroute.app.inputs import population_of
    from trustroute.policies.belief.driver_types import lift_population, lift_spec
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.synthesis.population import per_type_values

    town = trustroute.load_town()
    population = population_of(POPULATION)
    pomdp = build_pomdp(town, lift_population(population))
    rows = []
    for spec_name in SPECS:
        spec = lift_spec(trustroute.load_spec(spec_name, town), population)
        for horizon in SMALL_HORIZONS:
            started = time.perf_counter()
            optimum = trustroute.synthesize(spec_name, town, population=population, horizon=horizon,
                                            tau=1e-6, time_limit=600)
            rows.append(row(spec_name, horizon, "optimum", optimum.type_values, population.weights,
                            time.perf_counter() - started) | {"gap": optimum.gap})
        runs = [(h, DEPTH, "lookahead") for h in (*SMALL_HORIZONS, FULL_HORIZON, HORIZON)]
        for horizon, depth, what in [(FULL_HORIZON, FULL_HORIZON, "full_lookahead"), *runs]:
            started = time.perf_counter()
            values = per_type_values(pomdp, spec, LookaheadPolicy(pomdp, spec, horizon, depth), population,
                                     horizon)
            rows.append(row(spec_name, horizon, what, values, population.weights,
                            time.perf_counter() - started) | {"depth": depth})
    return rows
