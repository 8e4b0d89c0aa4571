"""The product POMDP of the trust model and a spec's DFA, explicit, as Storm's DRN (docs/trust_states.md).

For specs whose atoms are all state predicates over X × Θ (road atoms and trust-state atoms; no
belief atoms) the problem "maximise P(spec accepted)" is plain POMDP reachability. A state is

    (started, x, θ, q, h, e[, k])

x the road (observed), θ the trust level index (hidden), q the DFA state after reading the
current position (hidden: it depends on θ), (h, e) the human action and AV performance seen on
the road just driven (observed, so the belief over θ can be updated), k the junctions driven
(observed; only for the bounded objective, which stops at k = H). An extra first step
(`begin`, from started = false) draws θ0 from the initial belief and reads position 0. Choosing
action slot a at x drives to x' = successor(x, a); with incident i of x',

    P(h, e, θ' | θ) = P(h | θ, i) P(e | θ, i) T[i][h][e](θ, θ'),   q' = δ(q, L(x', θ')),

the same equations as the exact filter (policies/model/trust_pomdp.py). The label "goal" holds
at accepting q; accepting states are absorbing in the DFA, so "F goal" is the spec's
satisfaction (within H junctions with the step counter). The states are enumerated in numpy
over the grid (x, θ, q, last (h, e)[, k]) and restricted to those reachable from `begin`;
Storm reads the DRN text (its explicit format). Probabilities are printed with `repr`, which
round-trips every double exactly, or (`to_drn(exact=True)`) as the rationals of `exact_factors`,
for Storm's exact engine.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from fractions import Fraction

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order

from trustroute.core import defaults
from trustroute.core.errors import InputError
from trustroute.policies.belief.driver_types import base_trust_index
from trustroute.policies.belief.exact_labels import exact_prior, exact_symbol_matrices, symbol_code
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP

GOAL_LABEL = "goal"
PROPERTY = f'Pmax=? [F "{GOAL_LABEL}"]'


def no_goal_note(peer: str) -> str:
    """Why `peer` was not run on a product no reachable state of which satisfies the spec: the
    answer is 0 exactly, and the peers reject a property whose label no state carries."""
    return ("no reachable state of the product satisfies the spec (no satisfying route fits the "
            f"horizon): the maximum probability is 0, and {peer} was not run")


def check_exportable(spec: Spec) -> None:
    """InputError unless every atom the spec's minimal DFA tests is a road or trust-state atom
    (a belief atom no state tests, like lowtrust in the paper's φ1, does not matter)."""
    dfa = build_dfa(spec)
    tested = {atom for q in range(dfa.n_states) for atom in dfa.tested_atoms(q)}
    belief = [a for a in spec.formula_atoms if a in spec.belief_atoms and a in tested]
    if belief:
        raise InputError(spec.source_path or spec.name, "formula",
                         f"belief atoms ({', '.join(belief)}) cannot be exported to a POMDP model: "
                         "the AV's belief is not a state of it",
                         "use road atoms and [trust_states] atoms only (docs/trust_states.md)")


def check_product_size(spec: Spec, shape: tuple[int, ...], horizon: int | None) -> None:
    """InputError naming --horizon, before anything is allocated, when the grid of the product
    (`shape`: roads, trust levels, DFA states, last (h, e), steps) has more states than
    defaults.MAX_PEER_PRODUCT: the export holds arrays over the whole grid, about 2 kB a state."""
    limit = defaults.MAX_PEER_PRODUCT
    n_grid = int(np.prod(shape, dtype=object))   # exact, however large the horizon
    if n_grid <= limit:
        return
    per_step = n_grid // shape[-1]
    largest = limit // per_step - 1
    fix = (f"pass --horizon {largest} or less, or use a smaller town" if largest >= 1
           else "use a smaller town or a spec with fewer DFA states")
    raise InputError(spec.source_path or spec.name, "--horizon" if horizon is not None else "product",
                     f"the product POMDP handed to the peer would have {n_grid:,} grid states "
                     f"({' x '.join(map(str, shape))}: roads, trust levels, DFA states, last (h, e), "
                     f"steps), more than the {limit:,} it is built within", fix)


@dataclass(frozen=True, eq=False)
class ExplicitProduct:
    """State 0 is `begin`. Choices are numbered in state order; choice c belongs to
    choice_state[c] and is labelled choice_label[c]; transition j goes from choice
    transition_choice[j] to transition_target[j] with probability transition_probability[j],
    exactly exact_factors[transition_factor[j]]. State s is on road road[s] after step[s]
    junctions (-1 at `begin`; the step is 0 throughout without a horizon)."""

    horizon: int | None
    observation: np.ndarray          # int [n_states]
    goal: np.ndarray                 # bool [n_states]
    choice_state: np.ndarray
    choice_label: tuple[str, ...]
    transition_choice: np.ndarray
    transition_target: np.ndarray
    transition_probability: np.ndarray
    transition_factor: np.ndarray
    exact_factors: tuple[Fraction, ...]
    road: np.ndarray
    step: np.ndarray
    query: str = PROPERTY

    @property
    def n_states(self) -> int:
        return int(self.observation.size)

    def rationals(self) -> tuple[Fraction, ...]:
        """`exact_factors`; ValueError for a product built without them."""
        if not self.exact_factors:
            raise ValueError("the product was built without its rationals: explicit_product(..., exact=True)")
        return self.exact_factors

    def to_drn(self, exact: bool = False) -> str:
        """The DRN text; `exact`: each probability as its rational (`exact_factors`)."""
        order = np.argsort(self.transition_choice, kind="stable")
        targets = self.transition_target[order]
        if exact:
            texts = [str(f) for f in self.rationals()]
            probabilities = [texts[code] for code in self.transition_factor[order].tolist()]
        else:
            probabilities = [repr(p) for p in self.transition_probability[order].tolist()]
        bounds = np.searchsorted(self.transition_choice[order], np.arange(self.choice_state.size + 1))
        first_choice = np.searchsorted(self.choice_state, np.arange(self.n_states + 1))
        lines = ["// the product POMDP of trustroute (docs/trust_states.md)", "@type: POMDP",
                 "@parameters", "", "@reward_models", "", "@nr_states", str(self.n_states),
                 "@nr_choices", str(self.choice_state.size), "@model"]
        for s in range(self.n_states):
            labels = (" init" if s == 0 else "") + (f" {GOAL_LABEL}" if self.goal[s] else "")
            lines.append(f"state {s} {{{int(self.observation[s])}}}{labels}")
            for c in range(first_choice[s], first_choice[s + 1]):
                lines.append(f"\taction {self.choice_label[c]}")
                lines.extend(f"\t\t{int(t)} : {p}" for t, p in
                             zip(targets[bounds[c]:bounds[c + 1]], probabilities[bounds[c]:bounds[c + 1]],
                                 strict=True))
        return "\n".join(lines) + "\n"


def explicit_product(pomdp: TrustPOMDP, spec: Spec, horizon: int | None = None,
                     exact: bool = False) -> ExplicitProduct:
    """The product; `exact`: with its probabilities as rationals too (`exact_factors`, for Storm's
    exact engine; without it the tuple is empty, as the peers' double-precision runs need none)."""
    check_exportable(spec)
    if horizon is not None and horizon < 0:
        raise ValueError(f"horizon must be >= 0, got {horizon}")
    town, driver = pomdp.town, pomdp.driver
    compiled = compile_spec(spec, town)
    dfa, labeller = compiled.dfa, compiled.labeller
    n_x, n_t, n_q = pomdp.n_states, pomdp.n_trust, int(dfa.n_states)
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if driver.depends_on_performance else (0,))]
    n_o, n_k = len(outcomes), (horizon + 1 if horizon is not None else 1)
    qs, xs, ts = np.meshgrid(np.arange(n_q), np.arange(n_x), np.arange(n_t), indexing="ij")
    # θ is the hidden index: with a driver population's type-aware model, (type, trust), whose
    # trust level the trust-state atoms read.
    levels = base_trust_index(driver)[ts.ravel()]
    next_q = np.asarray(labeller.step(qs.ravel(), xs.ravel(), np.zeros((qs.size, n_t)), levels),
                        dtype=np.int64).reshape(n_q, n_x, n_t)
    shape = (n_x, n_t, n_q, n_o, n_k)
    check_product_size(spec, shape, horizon)
    n_grid = int(np.prod(shape))

    def index(x: np.ndarray, t: np.ndarray, q: np.ndarray, o: np.ndarray, k: np.ndarray) -> np.ndarray:
        return 1 + np.ravel_multi_index((x, t, q, o, k), shape)

    # The begin state: θ0 ~ initial belief, position 0 read with it.
    start = town.state_index(spec.start)
    b0 = np.asarray(pomdp.initial_belief, dtype=float)
    t0 = np.flatnonzero(b0 > 0)
    q0 = next_q[dfa.initial, start, t0]
    choice_state = [np.zeros(1, dtype=np.int64)]
    choice_label: list[np.ndarray] = [np.array(["begin"])]
    tr_choice = [np.zeros(t0.size, dtype=np.int64)]
    tr_target = [index(np.full(t0.size, start), t0, q0, np.zeros(t0.size, dtype=np.int64),
                       np.zeros(t0.size, dtype=np.int64))]
    tr_prob = [b0[t0]]
    n_inc = pomdp.observation_likelihood.shape[0]
    factor_shape = (n_inc, n_o, n_t, n_t)                   # codes 1 + n_t + (incident, o, θ, θ')
    tr_factor = [1 + t0]

    # Every grid state: x, t, q, o, k.
    grid = np.arange(n_grid)
    gx, gt, gq, go, gk = np.unravel_index(grid, shape)
    moving = gk < n_k - 1 if horizon is not None else np.ones(n_grid, dtype=bool)
    p_branch = (pomdp.observation_likelihood[:, [h for h, _ in outcomes], [e for _, e in outcomes], :]
                [..., None] * driver.trust_transition[:, [h for h, _ in outcomes],
                                                      [e for _, e in outcomes]])  # [inc, o, θ, θ']
    next_choice = 1
    slots = pomdp.successor_table.shape[1]
    per_state_choices = np.zeros(n_grid, dtype=np.int64)
    choice_blocks = []
    for slot in range(slots):
        x2 = pomdp.successor_table[gx, slot]
        has = moving & (x2 >= 0)
        per_state_choices += has
        choice_blocks.append((slot, has, x2))
    # Choices are numbered state by state (slots in order), as DRN lists them.
    stopping = ~moving
    n_choices_grid = per_state_choices + stopping
    first = 1 + np.concatenate([[0], np.cumsum(n_choices_grid)[:-1]])
    offset = np.zeros(n_grid, dtype=np.int64)
    labels_grid = np.empty(int(n_choices_grid.sum()), dtype=object)
    for slot, has, x2 in choice_blocks:
        states = np.flatnonzero(has)
        choice = first[states] + offset[states]
        offset[states] += 1
        labels_grid[choice - 1] = f"go{slot}"
        inc2 = pomdp.road_incident[x2[states]]
        probs = p_branch[inc2, :, gt[states], :]                    # [m, o, θ']
        m, o2, t2 = np.nonzero(probs > 0)
        tr_choice.append(choice[m])
        tr_target.append(index(x2[states][m], t2, next_q[gq[states][m], x2[states][m], t2], o2,
                               np.minimum(gk[states][m] + (horizon is not None), n_k - 1)))
        tr_prob.append(probs[m, o2, t2])
        tr_factor.append(1 + n_t + np.ravel_multi_index((inc2[m], o2, gt[states][m], t2), factor_shape))
    stop_states = np.flatnonzero(stopping)
    if stop_states.size:
        choice = first[stop_states] + offset[stop_states]
        labels_grid[choice - 1] = "stop"
        tr_choice.append(choice)
        tr_target.append(1 + stop_states)
        tr_prob.append(np.ones(stop_states.size))
        tr_factor.append(np.zeros(stop_states.size, dtype=np.int64))
    next_choice += labels_grid.size
    choice_state.append(np.repeat(1 + grid, n_choices_grid))
    choice_label.append(labels_grid)
    c_state = np.concatenate(choice_state)
    c_label = np.concatenate(choice_label)
    t_choice, t_target, t_prob, t_factor = (np.concatenate(a) for a in (tr_choice, tr_target, tr_prob,
                                                                        tr_factor))

    # Every grid state, unreached ones included; `reached_part` keeps those reached from begin.
    n_all = 1 + n_grid
    # the observation (started, x, o, k) as one code, in the order of its fields
    observation = np.zeros(n_all, dtype=np.int64)
    observation[1:] = np.ravel_multi_index((1 + gx, go, gk), (1 + n_x, n_o, n_k))
    goal = np.zeros(n_all, dtype=bool)
    goal[1:] = np.asarray(dfa.accepting, dtype=bool)[gq]
    road, step = np.full(n_all, -1, dtype=np.int64), np.full(n_all, -1, dtype=np.int64)
    road[1:], step[1:] = gx, gk
    return reached_part(ExplicitProduct(
        horizon=horizon, observation=observation, goal=goal, choice_state=c_state,
        choice_label=tuple(c_label.tolist()), transition_choice=t_choice, transition_target=t_target,
        transition_probability=t_prob, transition_factor=t_factor,
        exact_factors=exact_factors(pomdp, outcomes) if exact else (), road=road, step=step))


def reached_part(product: ExplicitProduct) -> ExplicitProduct:
    """The part of `product` reached from `begin` (state 0), as the class lays a product out: its
    states renumbered in order, its choices in state order (a state's in the order given), its
    observations numbered 0, 1, ... in the order of their codes. `product` may hold states never
    reached, choices in any order and any integer codes of observations: what the enumeration of
    the grid and a policy's chain (`induced_chain`) each build."""
    c_state, t_choice = product.choice_state, product.transition_choice
    reached = _reached_from_begin(product.n_states, c_state[t_choice], product.transition_target)
    order = np.argsort(c_state, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    new_id = np.cumsum(reached) - 1
    keep_choice = reached[c_state[order]]
    new_choice = np.cumsum(keep_choice) - 1
    keep = reached[c_state[t_choice]]
    return ExplicitProduct(
        horizon=product.horizon, goal=product.goal[reached],
        observation=np.unique(product.observation[reached], return_inverse=True)[1].ravel().astype(np.int64),
        choice_state=new_id[c_state[order][keep_choice]],
        choice_label=tuple(np.asarray(product.choice_label, dtype=object)[order][keep_choice].tolist()),
        transition_choice=new_choice[rank[t_choice[keep]]],
        transition_target=new_id[product.transition_target[keep]],
        transition_probability=product.transition_probability[keep],
        transition_factor=product.transition_factor[keep], exact_factors=product.exact_factors,
        road=product.road[reached], step=product.step[reached])


def _reached_from_begin(n_states: int, source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """bool [n_states]: the states reached from state 0 along the transitions source -> target."""
    graph = csr_matrix((np.ones(source.size), (source, target)), shape=(n_states, n_states))
    reached = np.zeros(n_states, dtype=bool)
    reached[breadth_first_order(graph, 0, return_predecessors=False)] = True
    return reached


def route_choices(product: ExplicitProduct, pomdp: TrustPOMDP, route: list[str]) -> np.ndarray:
    """int [n_states]: the choice of each state under the policy that drives `route` (road names,
    the start road first) junction by junction and ends the episode at its last road, as the
    trust-free baseline does at its destination (policies/routing/free.py); -1 where the episode
    ends (the route's end, or the horizon). Needs the step counter (a horizon), by which a state
    knows how far along the route it is."""
    if product.horizon is None:
        raise ValueError("a route's choices need the product's step counter: pass a horizon")
    town = pomdp.town
    roads = np.array([town.state_index(r) for r in route], dtype=np.int64)
    choices = np.full(product.n_states, -1, dtype=np.int64)
    choices[0] = 0                                                  # begin
    labels = np.asarray(product.choice_label)
    for k in range(min(len(route) - 1, product.horizon)):
        slots = np.flatnonzero(pomdp.successor_table[roads[k]] == roads[k + 1])
        if slots.size == 0:
            raise ValueError(f"{route[k + 1]} does not follow {route[k]} in the town")
        here = np.flatnonzero((product.step[product.choice_state] == k)
                              & (product.road[product.choice_state] == roads[k])
                              & (labels == f"go{int(slots[0])}"))
        choices[product.choice_state[here]] = here
    return choices


def induced_chain(product: ExplicitProduct, choices: np.ndarray) -> ExplicitProduct:
    """The Markov chain of the product under one choice per state (`choices`, as `route_choices`
    gives them): each state keeps its chosen choice, or (-1) ends the episode in a self-loop
    labelled `end`, restricted to the states reached from `begin`. Its value P(F goal) is the
    value of that policy (a reachability probability in a finite chain)."""
    ends = np.flatnonzero(choices < 0)
    kept = np.zeros(product.choice_state.size, dtype=bool)
    kept[choices[choices >= 0]] = True
    keep_tr = kept[product.transition_choice]
    # old choices first, then one new `end` choice per ending state (`reached_part` orders them by state)
    c_state = np.concatenate([product.choice_state[kept], ends])
    c_label = np.concatenate([np.asarray(product.choice_label, dtype=object)[kept],
                              np.full(ends.size, "end", dtype=object)])
    old_to_new = np.cumsum(kept) - 1
    t_choice = np.concatenate([old_to_new[product.transition_choice[keep_tr]],
                               int(kept.sum()) + np.arange(ends.size)])
    t_target = np.concatenate([product.transition_target[keep_tr], ends])
    t_prob = np.concatenate([product.transition_probability[keep_tr], np.ones(ends.size)])
    t_factor = np.concatenate([product.transition_factor[keep_tr], np.zeros(ends.size, dtype=np.int64)])
    return reached_part(replace(product, choice_state=c_state, choice_label=tuple(c_label.tolist()),
                                transition_choice=t_choice, transition_target=t_target,
                                transition_probability=t_prob, transition_factor=t_factor))


def exact_factors(pomdp: TrustPOMDP, outcomes: list[tuple[int, int]]) -> tuple[Fraction, ...]:
    """The product's probabilities as rationals, in the codes of `transition_factor`: 1 (the
    stop), the exact prior (`exact_prior`), then per (incident, observation o = (h, e), θ, θ')
    P(o, θ' | θ, incident) = ℓ_o(θ) T_o(θ, θ') from the model's decimals (`exact_symbol_matrices`,
    the exact process of docs/synthesis.md, "Labels at thresholds"), each (incident, θ) row divided
    by its sum. Where every transition row sums to 1 as printed the division changes nothing; where
    one does not (the packaged model's sum to 1 within an ulp) it makes the row a distribution, as
    a Markov chain and Storm's exact engine need."""
    matrices, _, _ = exact_symbol_matrices(pomdp, "bayes")
    n_inc, n_t = pomdp.observation_likelihood.shape[0], pomdp.n_trust
    table = np.empty((n_inc, len(outcomes), n_t, n_t), dtype=object)
    for i in range(n_inc):
        for o, (h, e) in enumerate(outcomes):
            table[i, o] = matrices[int(symbol_code(i, h, e))]
        for t in range(n_t):
            total = sum(table[i, :, t].ravel().tolist(), Fraction(0))
            if total:
                table[i, :, t] = [[value / total for value in row] for row in table[i, :, t].tolist()]
    return (Fraction(1), *exact_prior(pomdp.driver), *table.ravel().tolist())
