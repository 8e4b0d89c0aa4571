"""Bounds on Pr_max for specs with trust-state atoms, by search over joint beliefs (docs/trust_states.md).

V(J) = max over policies of P(accepted), J the joint belief over (θ, q) of
policies/belief/trust_state_filter.py (with the road and, under a non-Bayes rule, the AV's belief).
The search unfolds the belief tree level by level to `depth` junctions, every action and every
observation, merging nodes whose (road, J, beliefs) are bit for bit equal (the optimal value
and decision depend on nothing else), then backs values up:

    V(node) = max over next junctions of Σ_o P(o | node) V(child_o).

Leaves: a settled node (no live mass) is worth J(accepting) exactly; a node at the depth or cut
off (probability below `prune_below`, or beyond `max_nodes` per level) is worth at least
J(accepting) — or, when no label reads the belief, the exact value of an open-loop continuation
that ignores observations and follows the relaxation's best move (to the horizon, or 30
junctions for the unbounded objective) — and at most J(accepting) + Σ_{live θ, q} J(θ, q) R(x, θ, q),
where R is the value of the relaxation that observes θ and q and may choose the value of every
belief atom — an upper bound on any policy's value from that state (`relaxed_values`). Lower
and upper are backed up separately; the lower one is the value of the policy taking the lower arg-max, so
lower <= Pr_max <= upper. With `horizon` = depth the objective is "accepted within H junctions"
and the result is exact (lower = upper) unless nodes were cut. R is computed by backward
induction (bounded) or by value iteration from above (unbounded), each iterate plus a margin of
1e-12 so that floating-point rounding cannot take it below the true value; the root's upper
value gets the same allowance.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from trustroute.policies.belief.exact_labels import symbol_code
from trustroute.policies.belief.trust_state_filter import JointFilter, distinct_nodes, joint_filter
from trustroute.policies.belief.trust_state_relaxation import (
    RELAXATION_MARGIN,
    InformedLeaves,
    RelaxedGuide,
    guide_of,
    relaxed_next_q,
    relaxed_values,
    trust_move,
)
from trustroute.policies.bracket import Bracket
from trustroute.policies.logic.compiled import CompiledSpec, compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.work_clock import installed, spend, stopped_by
from trustroute.policies.work_clock import now as clock_now


@dataclass(frozen=True)
class JointBounds(Bracket):
    """A search's bounds, its reach (depth, horizon), the nodes it made and cut, its wall-clock
    seconds, and what ended it (`stopped_by`, work_clock.stopped_by's words): "convergence" (no node
    with live mass left unexpanded within its reach: the bounds are exact but for rounding), "node
    cap" (nodes cut beyond `max_nodes` a level or below `prune_below`), "depth cap" (unbounded: live
    nodes at the depth, valued by the relaxation), or the limit its deadline stood for ("time
    limit", or "work limit" under a work clock): the deadline left nodes unexpanded or leaves
    unvalued, so a longer limit could tighten the bounds."""

    lower: float
    upper: float
    depth: int
    horizon: int | None
    nodes: int
    cut_nodes: int
    seconds: float
    belief_rule: str
    stopped_by: str


OPEN_LOOP_STEPS = 30          # junctions of the open-loop continuation at unbounded leaves
OPEN_LOOP_CHUNK = 4_000       # nodes per vectorised batch of the open-loop continuation
EXPAND_SHARE = 0.5            # with a deadline: share of the time for the forward pass
CHILD_UNITS = 20              # units of work (policies/work_clock.py) per node expanded


@dataclass(frozen=True, eq=False)
class OpenLoop:
    """The policy that ignores observations and moves, at each step, to the successor with the
    largest relaxed value `guide(k)` (k junctions left after the move): `next_q` [n_q, n_x] the
    DFA's successor on a road (labels that do not read the belief), `move` [incident, θ, θ'] the
    trust move summed over observations, `accepting` the DFA's accepting states."""

    pomdp: TrustPOMDP
    next_q: np.ndarray
    move: np.ndarray
    guide: Callable[[int], np.ndarray]
    accepting: np.ndarray

    def accepted(self, x: np.ndarray, joint: np.ndarray, steps: int) -> np.ndarray:
        """P(accepted within `steps` more junctions) from each node (road x, joint J). The labels
        must not depend on the belief (then the observations can be summed out). Exact for that
        policy, so a lower bound on the optimum from each node."""
        n, n_t, n_q = joint.shape
        rows = np.arange(n)[:, None]
        thetas = np.arange(n_t)[None, :]
        pomdp, next_q, move = self.pomdp, self.next_q, self.move
        successors = pomdp.successor_table
        for k in range(steps):
            table = self.guide(steps - k - 1)
            best_score = np.full(n, -np.inf)
            best_joint = joint
            best_x = x
            for slot in range(successors.shape[1]):
                x2 = successors[x, slot]
                valid = x2 >= 0
                if not valid.any():
                    continue
                x2 = np.where(valid, x2, 0)
                predicted = np.einsum("ntq,ntu->nuq", joint, move[pomdp.road_incident[x2]])
                moved = np.zeros_like(predicted)
                for q in range(n_q):
                    moved[rows, thetas, next_q[q][x2]] += predicted[:, :, q]
                score = np.where(valid, np.einsum("ntq,ntq->n", moved, table[x2]), -np.inf)
                better = score > best_score
                best_score = np.where(better, score, best_score)
                best_joint = np.where(better[:, None, None], moved, best_joint)
                best_x = np.where(better, x2, best_x)
            joint, x = best_joint, best_x
        return joint[:, :, self.accepting].sum(axis=(1, 2))

    def values(self, x: np.ndarray, joint: np.ndarray, steps: int, budget: TimeBudget) -> np.ndarray:
        """`accepted` chunk by chunk, 0 (no claim) for the chunks past the deadline. It spends no
        work: `charged` spends it where the values are used."""
        out = np.zeros(x.size)
        for part in _chunks_in_time(x.size, budget):
            out[part] = self.accepted(x[part], joint[part], steps)
        return out

    @staticmethod
    def charged(values: np.ndarray, steps: int, budget: TimeBudget) -> tuple[np.ndarray, bool]:
        """`values` (of `values`, computed earlier) as if computed now: chunk by chunk, each chunk
        spending its work, 0 for the chunks past the deadline; and whether no chunk was. The clock
        only moves on, so a chunk this uses was valued by `values` too."""
        out = np.zeros(values.size)
        end = 0
        for part in _chunks_in_time(values.size, budget):
            out[part] = values[part]
            spend(steps * out[part].size)
            end = part.stop
        return out, end >= values.size


def _chunks_in_time(size: int, budget: TimeBudget) -> Iterator[slice]:
    """The OPEN_LOOP_CHUNK slices of `size` rows, until the budget's deadline (checked before each):
    `OpenLoop.values` and `OpenLoop.charged` cut their rows alike."""
    for begin in range(0, size, OPEN_LOOP_CHUNK):
        if budget.expired():
            return
        yield slice(begin, begin + OPEN_LOOP_CHUNK)


@dataclass(frozen=True)
class JointLimits:
    """Where the trust-state search stops unfolding: nodes of probability below `prune_below`, and
    those beyond the `max_nodes` likeliest of a level, are cut; with a guide the next
    `guided_nodes` of a level follow the guide's action instead; `deadline` (on the synthesis'
    clock, policies/work_clock.py; None: none) ends the search (`joint_search`)."""

    prune_below: float = 0.0
    max_nodes: int = 200_000
    guided_nodes: int = 0
    deadline: float | None = None


NO_LIMITS = JointLimits()


@dataclass(frozen=True, eq=False)
class JointDecisions:
    """The search's lower-greedy decision at each expanded node: t (junctions driven), road x,
    joint belief J [rows, n_trust, n_q], AV belief [rows, n_trust] and the action slot (index into
    the successors of x) whose backed-up lower value is the largest (ties: the larger upper, then
    the first slot)."""

    t: np.ndarray
    x: np.ndarray
    joint: np.ndarray
    beliefs: np.ndarray
    action: np.ndarray


def _children(pomdp: TrustPOMDP, filter_: JointFilter, belief_rule: BeliefRule, nodes: dict,
              parents: np.ndarray, follow: np.ndarray) -> tuple[np.ndarray, ...]:
    """The children of `parents` (indices into the level `nodes`) along every action, or the
    guide's alone where `follow` names one, per observation of positive probability: (parent,
    slot, road, J, posterior, AV belief, its word, P(o), reach mass). Under Bayes' rule the AV
    belief is the posterior, the same array."""
    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if pomdp.driver.depends_on_performance else (0,))]
    bayes = belief_rule == "bayes"
    columns: list[list[np.ndarray]] = [[] for _ in range(9)]
    for slot in range(pomdp.successor_table.shape[1]):
        x2 = pomdp.successor_table[nodes["x"][parents], slot]
        has = (x2 >= 0) & ((follow[parents] < 0) | (follow[parents] == slot))
        p_idx, x2 = parents[has], x2[has]
        incident = pomdp.road_incident[x2]
        for h, e in outcomes:
            posterior, p_obs = pomdp.belief_update(nodes["posterior"][p_idx], incident, h, e)
            belief = posterior if bayes else pomdp.posterior(nodes["belief"][p_idx], incident, h, e,
                                                             rule=belief_rule)
            ok = p_obs > 0
            labels = filter_.labels(belief_rule)
            # a history's word decides only belief labels: without them every node has the empty
            # word, and the filter interns none (some 400,000 words on the 5 x 5 grid otherwise)
            words = (labels.filter.extend(nodes["word"][p_idx][ok], symbol_code(incident[ok], h, e))
                     if filter_.labeller.belief_columns.size else np.zeros(int(ok.sum()), dtype=np.int64))
            joint = filter_.update(nodes["joint"][p_idx][ok], posterior[ok], belief[ok], x2[ok],
                                   (incident[ok], h, e), p_obs[ok], words, labels)
            part = (p_idx[ok], np.full(int(ok.sum()), slot), x2[ok], joint, posterior[ok],
                    None if bayes else belief[ok], words, p_obs[ok], nodes["mass"][p_idx][ok] * p_obs[ok])
            for column, piece in zip(columns, part, strict=True):
                column.append(piece)
    # One field at a time, each field's pieces dropped once joined: a level's children are
    # hundreds of thousands of rows, and joining all fields at once would hold them twice.
    out: list[np.ndarray] = []
    for j, column in enumerate(columns):
        out.append(out[4] if bayes and j == 5 else np.concatenate(column))
        column.clear()
    return tuple(out)


def _back_up(edges: tuple[np.ndarray, ...], grow: np.ndarray, follow: np.ndarray, slots: int,
             lower: np.ndarray, upper: np.ndarray, low: np.ndarray, high: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One level's backup from its children's (lower, upper): the level's (low, high), leaf
    bounds where nothing was expanded, and the lower-greedy slot per node (ties: the larger
    upper, then the first slot)."""
    parent, slot_of, child, p_obs = edges
    n = low.size
    sum_low = np.zeros((n, slots))
    sum_high = np.zeros((n, slots))
    np.add.at(sum_low, (parent, slot_of), p_obs * lower[child])
    np.add.at(sum_high, (parent, slot_of), p_obs * upper[child])
    has = np.zeros((n, slots), dtype=bool)
    has[parent, slot_of] = True
    best_low = np.where(has, sum_low, -np.inf).max(axis=1)
    best_high = np.where(has, sum_high, -np.inf).max(axis=1)
    tied = has & (sum_low >= best_low[:, None])
    slot = np.where(tied, sum_high, -np.inf).argmax(axis=1)
    # Nodes that follow the guide: worth what its action gives (lower); the relaxation
    # stays their upper bound (the optimum may act otherwise).
    along = np.flatnonzero(follow >= 0)
    low[along] = sum_low[along, follow[along]]
    low = np.where(grow, best_low, low)
    high = np.where(grow, np.minimum(1.0, best_high), high)
    return low, high, slot


SlotBounds = Callable[[np.ndarray, np.ndarray, int], np.ndarray]   # (x, live joint, left) -> [n, slots]


def _slot_bounds(pomdp: TrustPOMDP, next_q: np.ndarray, relaxed: np.ndarray, accepting: np.ndarray,
                 rejecting: np.ndarray, horizon: int | None) -> SlotBounds:
    """The bounds of the slots of leaves (x, live joint belief, junctions left). Within a horizon:
    InformedLeaves (the next two junctions chosen on the belief, then the relaxation that learns θ
    and q a junction late); unbounded: the next junction chosen on the belief, then the relaxation
    that observes θ and q. Built at the first leaf: a search that cuts no node has none."""
    built: list[SlotBounds] = []   # this search's own, built at its first leaf

    def slot_values(x: np.ndarray, joint: np.ndarray, left: int) -> np.ndarray:
        if not built:
            built.append(InformedLeaves.of(pomdp, next_q, accepting, rejecting, horizon).slot_values
                         if horizon is not None else guide_of(pomdp, next_q, relaxed, horizon).action_values)
        return built[0](x, joint, left)
    return slot_values


def _leaf_upper(accepted: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A leaf's upper bound from its accepted mass and its slots' bounds `values` [n, slots] (the
    best slot; a road without successors ends the drive, where only what is accepted counts)."""
    optimistic = np.maximum(values.max(axis=1), 0.0) + RELAXATION_MARGIN
    return np.minimum(1.0, accepted + optimistic)


@dataclass(eq=False)
class _Leaves:
    """How one search values its leaves. Lower: a leaf's accepted mass, or where the labels do
    not read the belief (`continuation`; else None) the value of the open-loop continuation
    (never with a guide's nodes, worth what the guide does). Upper: the relaxation's bound from its
    slots (`slot_values`). `valuing`: the clock's seconds the continuation took in the forward
    pass (`keep`), which the expansion's share does not count; `late`: whether the deadline left
    a leaf without it."""

    depth: int
    horizon: int | None
    accepting: np.ndarray
    live_q: np.ndarray
    slot_values: SlotBounds
    continuation: OpenLoop | None
    budget: TimeBudget
    valuing: float = 0.0
    late: bool = False      # a leaf's continuation was left unvalued, past the deadline (`finish`)

    @classmethod
    def of(cls, pomdp: TrustPOMDP, spec: Spec, compiled: CompiledSpec, reach: tuple[int, int | None],
           budget: TimeBudget) -> _Leaves:
        """The leaves of a search of `spec` (compiled) to `reach` = (depth, horizon)."""
        depth, horizon = reach
        dfa, labeller = compiled.dfa, compiled.labeller
        relaxed = relaxed_values(pomdp, spec, horizon)
        accepting = np.asarray(dfa.accepting, dtype=bool)
        rejecting = np.asarray(dfa.rejecting, dtype=bool) & ~accepting
        relaxed_q = relaxed_next_q(pomdp, spec, dfa, labeller)

        def relaxed_at(k: int) -> np.ndarray:
            return relaxed[min(k, horizon)] if horizon is not None else relaxed

        continuation = (OpenLoop(pomdp, relaxed_q[..., 0], trust_move(pomdp), relaxed_at, accepting)
                        if bool(np.all(relaxed_q == relaxed_q[..., :1])) else None)
        return cls(depth=depth, horizon=horizon, accepting=accepting, live_q=~(accepting | rejecting),
                   slot_values=_slot_bounds(pomdp, relaxed_q, relaxed, accepting, rejecting, horizon),
                   continuation=continuation, budget=budget)

    def bounds(self, x: np.ndarray, joint: np.ndarray, left: int,
               bounded: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of nodes: their accepted mass, and for the `bounded` ones (with live mass)
        with a junction left, the relaxation's bound (the other nodes' upper bound is their
        accepted mass, or their children's backup once expanded)."""
        accepted = joint[:, :, self.accepting].sum(axis=(1, 2))
        high = accepted.copy()
        which = bounded & (self.horizon is None or left > 0)
        if which.any():
            live = joint[which] * self.live_q
            high[which] = _leaf_upper(accepted[which], self.slot_values(x[which], live, left))
        return accepted, high

    def steps(self, left: int) -> int:
        """Junctions of the open-loop continuation at a leaf with `left` junctions to the depth."""
        return left if self.horizon is not None else OPEN_LOOP_STEPS

    def keep(self, nodes: dict, level: int, grow: np.ndarray, follow: np.ndarray, alive: np.ndarray) -> dict:
        """What the backward pass reads of a level once its expansion is decided: its nodes' leaf
        bounds, the open-loop values of its leaves, and its expanded nodes' roads, joint and AV
        beliefs (the decisions). So the joint beliefs of the cut nodes, 28 floats or more each,
        are not held to the end of the search. Neither valuation spends work here: the
        continuation's work is spent in the backward pass (`finish`), where it was scheduled."""
        left = self.depth - level
        low, high = self.bounds(nodes["x"], nodes["joint"], left, ~grow & alive)
        # the leaves that get the continuation: none without one, or at the horizon
        continuation = self.continuation if self.horizon is None or left > 0 else None
        leaf = np.flatnonzero(~grow & (follow < 0) & alive & (continuation is not None))
        values = np.zeros(0)
        if continuation is not None and leaf.size:
            started = clock_now()
            values = continuation.values(nodes["x"][leaf], nodes["joint"][leaf], self.steps(left),
                                         self.budget)
            self.valuing += clock_now() - started
        return dict(low=low, high=high, x=nodes["x"][grow], joint=nodes["joint"][grow],
                    belief=nodes["belief"][grow], leaf=leaf, values=values)

    def finish(self, part: dict, level: int) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of a level's nodes with its leaves valued, the continuation's work spent
        (`part` from `keep`, its bounds handed over)."""
        low, high, leaf, values = part.pop("low"), part.pop("high"), part.pop("leaf"), part.pop("values")
        if leaf.size:
            charged, whole = OpenLoop.charged(values, self.steps(self.depth - level), self.budget)
            low[leaf] = np.maximum(low[leaf], charged)
            self.late |= not whole
        return low, high


def joint_bounds(pomdp: TrustPOMDP, spec: Spec, depth: int, horizon: int | None = None,
                 belief_rule: BeliefRule = "bayes", prune_below: float = 0.0,
                 max_nodes: int = JointLimits.max_nodes) -> JointBounds:
    """[lower, upper] on max over policies of P(accepted) (within `horizon` junctions when given;
    then depth = horizon)."""
    return joint_search(pomdp, spec, depth, horizon, belief_rule,
                        JointLimits(prune_below=prune_below, max_nodes=max_nodes))[0]


def joint_search(pomdp: TrustPOMDP, spec: Spec, depth: int, horizon: int | None = None,
                 belief_rule: BeliefRule = "bayes", limits: JointLimits = NO_LIMITS,
                 guide: RelaxedGuide | None = None) -> tuple[JointBounds, JointDecisions]:
    """joint_bounds, and the lower-greedy decisions at the expanded nodes (JointDecisions), within
    `limits` (prune_below, max_nodes, guided_nodes, deadline: JointLimits).

    With a `guide` (the acting rule of the joint policy off its stored rows), the nodes ranked
    just below the `max_nodes` likeliest of a level (up to `guided_nodes` more) are expanded
    with the guide's action only, and their lower value is that action's backed-up value: the
    lower bound is then the value of exactly the policy JointTablePolicy builds from the
    decisions (stored action at fully expanded nodes, the guide's elsewhere), short of the
    nodes beyond both caps, which are worth their accepted mass (at most that policy's value
    there). Without a guide, cut nodes are leaves valued by the open-loop continuation.

    With a `deadline` (on the synthesis' clock) the search returns by it, up to one level's or one
    chunk's work: past EXPAND_SHARE of the time left, checked before each level is expanded, the
    open nodes of that level become leaves worth their accepted mass (lower) and the relaxation
    (upper); past the deadline, the leaves not yet valued by the open-loop continuation keep
    their accepted mass. The bounds stay sound either way."""
    prune_below, max_nodes, guided_nodes = limits.prune_below, limits.max_nodes, limits.guided_nodes
    budget = TimeBudget.until(math.inf if limits.deadline is None else limits.deadline)
    if horizon is not None:
        depth = horizon
    compiled = compile_spec(spec, pomdp.town)
    filter_ = joint_filter(pomdp, compiled.dfa, compiled.labeller)
    leaves = _Leaves.of(pomdp, spec, compiled, (depth, horizon), budget)
    slots = pomdp.successor_table.shape[1]
    start = pomdp.town.state_index(spec.start)
    b0 = np.asarray(pomdp.initial_belief, dtype=float)[None, :]
    levels = [dict(x=np.array([start]), joint=filter_.initial(start, b0[0]), posterior=b0.copy(),
                   belief=b0.copy(), word=np.zeros(1, dtype=np.int64), mass=np.ones(1))]
    kept: list[dict] = []   # per level: what the backward pass reads of it (_Leaves.keep)
    edges: list[tuple[np.ndarray, ...]] = []   # per level: (parent, slot, child, p_obs) of its children
    expandable = []     # per level: bool per node, expanded with every action
    guided_slot = []    # per level: the guide's action slot per node expanded with it alone, else -1
    cut_total = 0
    pruned = 0          # open nodes below prune_below, leaves
    n_nodes = 0
    stopped = False     # the expansion's time is up: no further level is expanded
    late = False        # ... and it left open nodes unexpanded
    live_at_depth = False

    # The expansion gets EXPAND_SHARE of the time, the open-loop values (computed as the levels are
    # made, their work spent in the backward pass) and the backward pass the rest.
    expand_until = budget.share(EXPAND_SHARE)
    for level in range(depth + 1):
        nodes = levels[-1]
        n_nodes += nodes["x"].size
        alive = filter_.masses(nodes["joint"])[2] > 0
        within = alive & (level < depth)
        open_ = within & (nodes["mass"] >= prune_below)
        pruned += int((within & ~open_).sum())
        live_at_depth = level == depth and bool(alive.any())
        if budget.expired(min(expand_until + leaves.valuing, budget.deadline)):
            stopped = True
            late = bool(open_.any())
            grow = np.zeros_like(open_)
        else:
            grow = open_ & ~nodes["frozen"] if "frozen" in nodes else open_
        follow = np.full(grow.size, -1, dtype=np.int64)
        if guide is not None and "guided" in nodes and not stopped:
            along = open_ & nodes["guided"]
            follow[along] = guide.policy_slots(level, nodes["x"][along], nodes["joint"][along])
        cut_total += int((open_ & ~grow).sum())
        expandable.append(grow)
        guided_slot.append(follow)
        kept.append(leaves.keep(nodes, level, grow, follow, alive))
        if level == depth or not (grow | (follow >= 0)).any():
            break
        parents = np.flatnonzero(grow | (follow >= 0))
        spend(CHILD_UNITS * parents.size)
        parent, slot_of, x2, joint, posterior, belief, words, p_obs, mass = _children(
            pomdp, filter_, belief_rule, nodes, parents, follow)
        # Merge children with bit-identical (road, J, posterior, AV belief) and one word.
        first, inverse = distinct_nodes(x2, joint, posterior, belief, words)
        merged_mass = np.bincount(inverse, weights=mass)
        merged_posterior = posterior[first]
        child = dict(x=x2[first], joint=joint[first], posterior=merged_posterior,
                     belief=merged_posterior if belief is posterior else belief[first],
                     word=words[first], mass=merged_mass)
        # the children before merging are not read again: not held while the next level's are made
        del x2, joint, posterior, belief, words, mass
        if first.size > max_nodes:      # keep the likeliest nodes; the others are cut
            order = np.argsort(-merged_mass, kind="stable")
            rank = np.empty(first.size, dtype=np.int64)
            rank[order] = np.arange(first.size)
            child["frozen"] = rank >= max_nodes
            if guide is not None:       # the next ones follow the guide, the rest are leaves
                child["guided"] = child["frozen"] & (rank < max_nodes + guided_nodes)
        levels[-1] = child
        # The edges' indices as int32, slots in the smallest type that holds them (a byte on any
        # town): half the bytes.
        edges.append((parent.astype(np.int32), slot_of.astype(np.min_scalar_type(slots)),
                      inverse.astype(np.int32), p_obs))
        del parent, slot_of, inverse, p_obs
    del levels

    # Backward: leaves by their bounds, expanded nodes by the best action's expectation.
    n_levels = len(kept)

    lower, upper = leaves.finish(kept[-1], n_levels - 1)
    decided: list[tuple[int, np.ndarray]] = []     # (level, slot)
    for level in range(n_levels - 2, -1, -1):
        low, high = leaves.finish(kept[level], level)
        low, high, slot = _back_up(edges[level], expandable[level], guided_slot[level], slots,
                                   lower, upper, low, high)
        edges[level] = ()
        decided.append((level, slot[expandable[level]]))
        lower, upper = low, high
    decided.sort(key=lambda item: item[0])
    n_t, n_q = pomdp.n_trust, filter_.n_q
    parts = [(np.full(slot.size, level, dtype=np.int64), kept[level]["x"], kept[level]["joint"],
              kept[level]["belief"], slot) for level, slot in decided]
    empty = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, n_t, n_q)),
             np.zeros((0, n_t)), np.zeros(0, dtype=np.int64))
    decisions = JointDecisions(*(np.concatenate([p[j] for p in parts]) if parts else empty[j]
                                 for j in range(5)))
    # The backed-up upper value is a float sum of products: allow for its rounding.
    bounds = JointBounds(lower=float(lower[0]), upper=min(1.0, float(upper[0]) + RELAXATION_MARGIN),
                         depth=depth, horizon=horizon,
                         nodes=n_nodes, cut_nodes=cut_total,
                         seconds=budget.elapsed(), belief_rule=belief_rule,
                         stopped_by=_search_stop(late or leaves.late, cut_total + pruned > 0,
                                                 horizon is None and live_at_depth))
    return bounds, decisions


def _search_stop(late: bool, cut: bool, open_end: bool) -> str:
    """What ended a search (JointBounds.stopped_by): the limit its deadline stood for when the
    deadline left a node unexpanded or a leaf unvalued (`late`), else a cap when nodes were `cut`
    or (unbounded) live nodes were left at the depth (`open_end`), else convergence."""
    cap = None if late else "node cap" if cut else "depth cap" if open_end else None
    return stopped_by(not (late or cut or open_end), installed(), cap=cap)

