"""Small problems whose unbounded value is known exactly: a choice, then loops the AV cannot leave.

A case (`loop_case`): the start road A-B turns only to B-C, whose incident the human reacts to at
random (its takeover and failure probabilities depend on the trust: four observations, each
informative); at C the AV picks one of two or three loops, C -> J1 -> ... -> Jm -> C -> J1 ...,
which `turns` keep it in for ever. On a loop's roads the human's reaction is certain (takeover and
failure probabilities 0 or 1 for every trust level), so the AV observes nothing there, while the
hidden trust keeps moving with the road's incident (a random transition matrix). The spec reads the
hidden trust on the loops' roads (formulas like tests/policies/trust_specs.py's, no belief atom), so
a loop's value is the probability that a finite Markov chain over (road, trust, DFA state) is
absorbed in acceptance: a linear system over the states that can reach acceptance (the others are
worth 0), solved here in Fractions.

Every number of the model is a multiple of 1/20 (each transition row sums to 1 exactly as the
decimals it prints as), so the exact process of docs/synthesis.md ("Labels at thresholds": the
model's decimals) is that chain. Two kinds of loop dynamics: `recurrent` (every entry positive: the
live mass decays geometrically and is never resolved, the unbounded case proper) and `rising` (the
trust rises at every loop road until 7: every branch is decided after finitely many junctions, so
the computed bounds are the exact value up to floating-point rounding alone).

`exact_loop_values` gives Pr_max (the best loop for each observation at B-C) and the exact value of
a JointTablePolicy, which acts at B-C on the vehicle's float joint filter (node_state.HiddenState,
as exact_joint.py drives it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from tests.policies.synthesis.exact_joint import _Joint
from tests.policies.synthesis.threshold_cases import _outcomes
from trustroute.networks.town import town_from_dict
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.exact_labels import decimal
from trustroute.policies.belief.trust_state_filter import joint_filter
from trustroute.policies.evaluation.node_state import hidden_root
from trustroute.policies.logic.spec import Spec, spec_from_text
from trustroute.policies.model.trust_pomdp import TrustPOMDP, build_pomdp

SCALE = 20                     # every probability of a case is k / SCALE
N_TRUST = 7
CHOICE_INCIDENT = "pedestrian"  # B-C: the one informative road
LOOP_INCIDENTS = ("obstacle", "truck")
FORMULAS = ("(!wary) U (a & trusting)", "(!wary) U (a & F (b & trusting))", "(!wary) U (a & X trusting)",
            "F (a & trusting)")


@dataclass(frozen=True)
class LoopCase:
    pomdp: TrustPOMDP
    spec: Spec
    kind: str                      # "recurrent" or "rising"
    choice_road: str               # B-C, where the AV picks a loop


def _row(rng: np.random.Generator, support: np.ndarray, positive: bool) -> np.ndarray:
    """A transition row of multiples of 1/SCALE summing to 1 exactly, on `support` (every entry
    of the support at least 1/SCALE when `positive`)."""
    counts = np.zeros(N_TRUST, dtype=np.int64)
    floor = 1 if positive else 0
    shares = rng.dirichlet(np.ones(support.size))
    counts[support] = floor + rng.multinomial(SCALE - floor * support.size, shares)
    return counts / SCALE


def _matrix(rng: np.random.Generator, kind: str) -> np.ndarray:
    if kind == "recurrent":
        return np.stack([_row(rng, np.arange(N_TRUST), True) for _ in range(N_TRUST)])
    # rising: from level k to some level above it (7 stays 7)
    return np.stack([_row(rng, np.arange(k + 1, N_TRUST) if k < N_TRUST - 1 else np.array([k]), False)
                     for k in range(N_TRUST)])


def _driver(rng: np.random.Generator, incident_types: tuple[str, ...], kind: str) -> DriverModel:
    k = len(incident_types)
    takeover = np.zeros((k, N_TRUST))
    failure = np.zeros((k, N_TRUST))
    transition = np.zeros((k, 2, 2, N_TRUST, N_TRUST))
    for i, incident in enumerate(incident_types):
        if incident == CHOICE_INCIDENT:
            takeover[i] = rng.integers(1, SCALE, size=N_TRUST) / SCALE
            failure[i] = rng.integers(1, SCALE // 2, size=N_TRUST) / SCALE
        else:   # a certain reaction: the AV learns nothing on these roads
            takeover[i] = float(rng.integers(2))
            failure[i] = float(rng.integers(2))
        for h in (0, 1):
            for e in (0, 1):
                transition[i, h, e] = (_matrix(rng, kind) if incident in LOOP_INCIDENTS
                                       else _matrix(rng, "recurrent"))
    prior = (1 + rng.multinomial(SCALE - N_TRUST, rng.dirichlet(np.ones(N_TRUST)))) / SCALE
    return DriverModel(trust_levels=tuple(range(1, N_TRUST + 1)), incident_types=incident_types,
                       takeover_probability=takeover, failure_probability=failure,
                       trust_transition=transition, initial_belief=prior,
                       trust_free_takeover_probability={}, source_path="<loop driver>")


def _town(rng: np.random.Generator, lengths: list[int]):
    """A-B -> B-C -> one of the loops C -> L{k}1 -> ... -> L{k}m -> C (`lengths`: each m)."""
    loops = [[f"L{k}{j}" for j in range(1, m + 1)] for k, m in enumerate(lengths)]
    names = ["A", "B", "C"] + [name for loop in loops for name in loop]
    angle = 2 * math.pi / len(names)
    junctions = {name: [400 * math.cos(i * angle), 400 * math.sin(i * angle)] for i, name in enumerate(names)}
    roads = [["A", "B"], ["B", "C"]]
    turns = {"A-B": ["C"], "B-C": [loop[0] for loop in loops]}
    for loop in loops:
        ring = ["C", *loop, "C"]
        for u, v, w in zip(ring[:-1], ring[1:], [*ring[2:], loop[0]], strict=True):
            if [u, v] not in roads and [v, u] not in roads:
                roads.append([u, v])
            turns[f"{u}-{v}"] = [w]
    incidents = {}
    for u, v in roads:
        for road in (f"{u}-{v}", f"{v}-{u}"):
            incidents[road] = "none"
    incidents["B-C"] = CHOICE_INCIDENT
    loop_roads = sorted(set(turns) - {"A-B", "B-C"})
    for road in loop_roads:
        incidents[road] = str(rng.choice(LOOP_INCIDENTS))
    town = town_from_dict({"junctions": junctions, "roads": roads, "incidents": incidents,
                           "turns": turns}, "<loop town>")
    return town, loop_roads


def loop_case(seed: int, incident_types: tuple[str, ...]) -> LoopCase:
    """The case of `seed`: even seeds recurrent, odd seeds rising; 2-3 loops of 1-3 junctions."""
    rng = np.random.default_rng(seed)
    kind = ("recurrent", "rising")[seed % 2]
    town, loop_roads = _town(rng, [int(m) for m in rng.integers(1, 4, size=int(rng.integers(2, 4)))])
    pomdp = build_pomdp(town, _driver(rng, incident_types, kind))
    a = sorted(rng.choice(loop_roads, size=max(1, len(loop_roads) // 2), replace=False).tolist())
    b = sorted(rng.choice(loop_roads, size=max(1, len(loop_roads) // 2), replace=False).tolist())
    high = sorted({int(v) for v in rng.integers(4, 8, size=2)} | ({7} if kind == "rising" else set()))
    low = sorted({int(v) for v in rng.integers(1, 4, size=2)})
    formula = FORMULAS[seed // 2 % len(FORMULAS)]
    text = (f'name = "loops"\nstart = "A-B"\nformula = "{formula}"\n'
            f"[states]\na = {a}\nb = {b}\n"
            f"[trust_states]\ntrusting = {{ trust = {high} }}\n"
            f"wary = {{ trust = {low} }}\n").replace("'", '"')
    return LoopCase(pomdp=pomdp, spec=spec_from_text(text, "<loop spec>", town), kind=kind, choice_road="B-C")


def _solve(matrix: list[dict[int, Fraction]], rhs: list[Fraction]) -> list[Fraction]:
    """x with matrix x = rhs (Gauss-Jordan in Fractions; the matrix is nonsingular), its rows sparse
    ({column: entry}, zeros left out): a road's rows reach the next road of its loop alone, so the
    loops' blocks never mix and a row operation touches a head's few entries, not every column."""
    n = len(rhs)
    rows = [dict(row) for row in matrix]
    rhs = list(rhs)
    holding: list[set[int]] = [set() for _ in range(n)]   # per column, the rows with an entry there
    for r, row in enumerate(rows):
        for c in row:
            holding[c].add(r)
    for col in range(n):
        pivot = min(r for r in holding[col] if r >= col)
        for c in set(rows[col]) | set(rows[pivot]):
            for r, other in ((col, pivot), (pivot, col)):
                (holding[c].add if c in rows[other] else holding[c].discard)(r)
        rows[col], rows[pivot] = rows[pivot], rows[col]
        rhs[col], rhs[pivot] = rhs[pivot], rhs[col]
        head, inverse = rows[col], 1 / rows[col][col]
        for c in head:
            head[c] *= inverse
        rhs[col] *= inverse
        for r in sorted(holding[col] - {col}):
            row, factor = rows[r], rows[r][col]
            for c, h in head.items():
                value = row.get(c, 0) - factor * h
                if value:
                    row[c] = value
                    holding[c].add(r)
                else:
                    row.pop(c, None)
                    holding[c].discard(r)
            rhs[r] -= factor * rhs[col]
    return rhs


class _Loops:
    """The absorption probabilities of the loops' chain over (road, trust, DFA state)."""

    def __init__(self, case: LoopCase) -> None:
        pomdp = case.pomdp
        self.model = _Joint(pomdp, case.spec)
        assert self.model.compiled.labeller.belief_columns.size == 0   # labels read (road, trust) only
        driver = pomdp.driver
        self.transition = {}
        for x in range(pomdp.n_states):
            i = int(pomdp.road_incident[x])
            if driver.incident_types[i] in LOOP_INCIDENTS:
                h, e = int(driver.takeover_probability[i, 0]), int(driver.failure_probability[i, 0])
                matrix = [[decimal(v) for v in row] for row in driver.trust_transition[i, h, e].tolist()]
                assert all(sum(row) == 1 for row in matrix)
                self.transition[x] = matrix
        assert all(int((pomdp.successor_table[x] >= 0).sum()) == 1 for x in self.transition)
        self.next = {x: int(pomdp.successor_table[x, 0]) for x in self.transition}
        self.accepting, self.live = self.model.accepting, self.model.live
        self.steps = {x: self.model.successors(x, self.model.av.prior) for x in self.transition}   # [q, θ]
        self.values = self._absorption()

    def _absorption(self) -> dict[tuple[int, int, int], Fraction]:
        """U(x, θ, q): P(accepted) entering loop road x from trust θ and DFA state q (q live)."""
        keys = [(x, t, q) for x in self.transition for t in range(N_TRUST) for q in np.flatnonzero(self.live)]
        keys = [(x, t, int(q)) for x, t, q in keys]
        # states from which acceptance is reachable; the others are worth 0 (the least fixed point)
        edges = {key: self._moves(*key) for key in keys}
        good = {key for key, moves in edges.items() if any(to == "accept" for _, to in moves)}
        grew = True
        while grew:
            grew = False
            for key, moves in edges.items():
                if key not in good and any(to in good for _, to in moves):
                    good.add(key)
                    grew = True
        order = sorted(good)
        index = {key: n for n, key in enumerate(order)}
        matrix: list[dict[int, Fraction]] = [{r: Fraction(1)} for r in range(len(order))]
        rhs = [Fraction(0)] * len(order)
        for key in order:
            r = index[key]
            for p, to in edges[key]:
                if to == "accept":
                    rhs[r] += p
                elif to in index:
                    matrix[r][index[to]] = matrix[r].get(index[to], 0) - p
        solved = _solve(matrix, rhs)
        return {key: solved[index[key]] if key in index else Fraction(0) for key in keys}

    def _moves(self, x: int, t: int, q: int) -> list[tuple[Fraction, object]]:
        """(probability, where to) of entering road x from (θ = t, q): "accept", "reject" or the
        next (road, θ', q') to enter."""
        out: list[tuple[Fraction, object]] = []
        for t2, p in enumerate(self.transition[x][t]):
            if p == 0:
                continue
            q2 = int(self.steps[x][q, t2])
            to = ("accept" if self.accepting[q2] else (self.next[x], t2, q2) if self.live[q2] else "reject")
            out.append((p, to))
        return out

    def enter(self, x: int, joint: tuple[int, ...]) -> Fraction:
        """P(accepted) entering loop road x from the (unnormalised, integer) joint law J(θ, q)."""
        n_q = self.model.n_q
        total = Fraction(0)
        for t in range(N_TRUST):
            for q in range(n_q):
                mass = joint[t * n_q + q]
                if mass == 0:
                    continue
                if self.accepting[q]:
                    total += mass
                elif self.live[q]:
                    total += mass * self.values[x, t, q]
        return total / sum(joint)


@dataclass(frozen=True)
class ExactLoopValues:
    optimum: Fraction       # Pr_max: the best loop for each observation at B-C
    policy: Fraction        # the value of the given policy (None: the optimum's)
    branches: int


def exact_loop_values(case: LoopCase, policy=None) -> ExactLoopValues:
    """Pr_max of the unbounded spec and, with `policy` (a JointTablePolicy, acting on the vehicle's
    float joint filter), its value, exactly."""
    pomdp, town = case.pomdp, case.pomdp.town
    loops = _Loops(case)
    model = loops.model
    start, choice = town.state_index(case.spec.start), town.state_index(case.choice_road)
    assert [int(s) for s in pomdp.successor_table[start] if s >= 0] == [choice]
    joint, belief = model.initial(start, None)
    vehicle = hidden_root(joint_filter(pomdp, model.dfa, model.compiled.labeller), start, "bayes")
    entries = [int(s) for s in pomdp.successor_table[choice] if s >= 0]
    optimum, chosen, branches = Fraction(0), Fraction(0), 0
    incident = int(pomdp.road_incident[choice])
    for h, e in _outcomes(pomdp.driver):
        probability, joint2, _ = model.step(joint, choice, belief, (incident, h, e))
        if probability == 0:
            continue
        branches += 1
        values = [loops.enter(x, joint2) for x in entries]
        optimum += probability * max(values)
        if policy is not None:
            road = np.array([choice])
            follow = vehicle.children(road, h, e, vehicle.observation_probability(road, h, e))
            slot = int(policy.action_slots(1, road, follow.joint, follow.belief)[0])
            chosen += probability * values[slot]
    return ExactLoopValues(optimum=optimum, policy=chosen if policy is not None else optimum,
                           branches=branches)
