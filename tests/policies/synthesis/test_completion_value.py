"""Cluster bounds on the trust-free completion's value against the exact observation tree.

The exact value is an independent recursion over observation sequences through the one filter
(TrustPOMDP.belief_update) and the labeller's strict labels, along the completion's road sequence.
The cluster bounds must bracket it from every road of seeded random small towns, with the default
merge grid (then they are nearly exact) and with a coarse grid that merges almost everything (then
the enclosures and the pessimistic labels at thresholds carry the soundness). End to end, the
returned policy of a search whose open nodes use coarse bounds is worth at least L.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from tests.policies.synthesis.test_synthesis_random import random_spec, random_town
from trustroute.policies.belief.product_mdp import build_product
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import free_completion, state_only_task
from trustroute.policies.synthesis import completion_value
from trustroute.policies.synthesis.belief_cells import apply_symbol, observation_symbols
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.completion_value import CompletionStarts, FreeRoute, completion_bounds
from trustroute.policies.synthesis.open_node_bounds import held_choice, policy_choice
from trustroute.policies.synthesis.settings import SynthesisSettings

HORIZON = 8
TOLERANCE = 1e-12


def exact_free_value(tables, symbols, route, x, q, p, belief, steps) -> float:
    if tables.accepting[q]:
        return 1.0
    if tables.rejecting[q] or steps == 0:
        return 0.0
    x2, p2 = int(route.next_road[x, q, p]), int(route.next_task[x, q, p])
    total = 0.0
    for symbol in symbols.by_incident[int(tables.pomdp.road_incident[x2])]:
        posterior, probability = apply_symbol(belief[None], symbols, symbol)
        if probability[0] <= 0:
            continue
        q2 = int(tables.step(np.array([q]), np.array([x2]), posterior)[0])
        total += float(probability[0]) * exact_free_value(tables, symbols, route, x2, q2, p2,
                                                          posterior[0], steps - 1)
    return total


def _problem(driver, seed):
    rng = np.random.default_rng(seed)
    town = random_town(rng)
    pomdp = build_pomdp(town, driver)
    spec = random_spec(rng, town, np.asarray(pomdp.initial_belief))
    tables = build_product(pomdp, spec)
    task = state_only_task(town, spec)
    # the free completion the synthesis values open nodes by (moves per (x, q, p))
    route = FreeRoute.build(tables, free_completion(town, spec).slot,
                            np.asarray(task.next_state, dtype=np.int64))
    return tables, observation_symbols(pomdp), route, task


@pytest.fixture(scope="module")
def exact_values(driver):
    """exact(seed): the exact tree's value from every road of `_problem(seed)`, each computed once
    per module (the recursion is most of these tests' CPU, and several tests, with several merge
    settings and deadlines, bracket the same seeds' values; it reads none of those settings)."""
    @functools.cache
    def exact(seed: int) -> np.ndarray:
        tables, symbols, route, task = _problem(driver, seed)
        belief = np.asarray(tables.pomdp.initial_belief, dtype=float)
        return np.array([exact_free_value(tables, symbols, route, x, tables.initial_q,
                                          task.initial_state, belief, HORIZON)
                         for x in range(tables.n_x)])

    return exact


def _bounds_and_exact(driver, exact_values, seed, deadline=None):
    tables, symbols, route, task = _problem(driver, seed)
    belief = np.asarray(tables.pomdp.initial_belief, dtype=float)
    roads = np.arange(tables.n_x)
    q = np.full(roads.size, tables.initial_q)
    p = np.full(roads.size, task.initial_state)
    steps = np.full(roads.size, HORIZON)
    starts = CompletionStarts(roads, q, p, np.repeat(belief[None], roads.size, 0), steps)
    bounds = completion_bounds(tables, symbols, route, starts, deadline)
    return bounds, exact_values(seed)


@pytest.mark.parametrize("seed", range(8))
def test_default_bounds_bracket_and_nearly_equal_the_exact_tree(driver, exact_values, seed, monkeypatch):
    bounds, exact = _bounds_and_exact(driver, exact_values, seed)
    assert np.all(bounds.lower <= exact + TOLERANCE)
    assert np.all(exact <= bounds.upper + TOLERANCE)
    # with room for every cluster (a few hundred sequences here; the default cap, 64, can be
    # exceeded), only equal beliefs merge on the default grid: the bounds are the exact value
    monkeypatch.setattr(completion_value, "CLUSTER_CAP", 4096)
    bounds, exact = _bounds_and_exact(driver, exact_values, seed)
    assert np.max(bounds.upper - bounds.lower) <= 1e-9
    assert np.all(bounds.lower <= exact + TOLERANCE) and np.all(exact <= bounds.upper + TOLERANCE)


@pytest.mark.parametrize("seed", range(12))
def test_coarse_merging_stays_sound(driver, exact_values, seed, monkeypatch):
    monkeypatch.setattr(completion_value, "INITIAL_RESOLUTION", 0.05)
    monkeypatch.setattr(completion_value, "CLUSTER_CAP", 3)
    bounds, exact = _bounds_and_exact(driver, exact_values, seed)
    assert np.all(bounds.lower <= exact + TOLERANCE), (bounds.lower, exact)
    assert np.all(exact <= bounds.upper + TOLERANCE), (exact, bounds.upper)


class _SteppedClock:
    """perf_counter that advances one second per call: a deadline of k stops the propagation
    before its (k + 1)-th junction step."""

    def __init__(self) -> None:
        self.now = -1.0

    def perf_counter(self) -> float:
        self.now += 1.0
        return self.now


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("steps_before_deadline", [0, 1, 3])
def test_bounds_stopped_by_the_deadline_stay_sound(driver, exact_values, seed, steps_before_deadline,
                                                   monkeypatch):
    monkeypatch.setattr(completion_value, "time", _SteppedClock())
    bounds, exact = _bounds_and_exact(driver, exact_values, seed, deadline=float(steps_before_deadline))
    assert np.all(bounds.lower <= exact + TOLERANCE), (bounds.lower, exact)
    assert np.all(exact <= bounds.upper + TOLERANCE), (exact, bounds.upper)


def test_bounds_stopped_by_the_deadline_are_looser(driver, exact_values, monkeypatch):
    """Stopped after one junction step, the mass in flight widens the bounds (the soundness test
    above is not vacuous); with no deadline they are nearly exact."""
    monkeypatch.setattr(completion_value, "time", _SteppedClock())
    stopped = [_bounds_and_exact(driver, exact_values, seed, deadline=1.0)[0] for seed in range(6)]
    assert sum(b.interrupted for b in stopped) >= 3
    assert max(float(np.max(b.straddle)) for b in stopped) > 0.01


def test_coarse_merging_loosens_where_labels_matter(driver, exact_values, monkeypatch):
    """The coarse grid does widen some bound (the soundness test above is not vacuous)."""
    monkeypatch.setattr(completion_value, "INITIAL_RESOLUTION", 0.05)
    monkeypatch.setattr(completion_value, "CLUSTER_CAP", 3)
    widest = max(float(np.max(_bounds_and_exact(driver, exact_values, seed)[0].straddle))
                 for seed in range(12))
    assert widest > 0.01


def test_paper_rule_is_refused(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    tables = build_product(pomdp, spec)
    task = state_only_task(pomdp.town, spec)
    route = FreeRoute.build(tables, np.where(task.next_slot >= 0, task.next_slot, 0),
                            np.asarray(task.next_state, dtype=np.int64))
    with pytest.raises(ValueError, match="Bayes"):
        completion_bounds(tables, observation_symbols(pomdp, "paper"), route,
                          CompletionStarts(np.array([0]), np.array([tables.initial_q]),
                                           np.array([task.initial_state]),
                                           np.asarray(pomdp.initial_belief)[None], np.array([3])))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["phi1", "phi2_strict"])
def test_policy_is_worth_l_with_coarse_completion_bounds(pomdp, packaged_optimum, name, monkeypatch):
    """Loose bounds at open nodes make the rule that holds rows to the free move bind; the returned
    policy (exact evaluation through the RoutingPolicy interface) is still worth at least L, and
    the brute-force optimum lies in [L, U]. H = 8: the brute force's optimum is shared with
    test_synthesis.py (each junction more triples its cost), and φ2_strict's [L, U] is then only
    2e-3 wide, a sharp check of U."""
    monkeypatch.setattr(completion_value, "INITIAL_RESOLUTION", 0.05)
    monkeypatch.setattr(completion_value, "CLUSTER_CAP", 3)
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    horizon = 8
    result = synthesize(pomdp, spec, SynthesisSettings(tau=0.05, horizon=horizon, completion="bounds"))
    value = evaluate(pomdp, spec, result.policy,
                     EvaluationSettings(fallback_after=None, max_junctions=horizon))
    assert value.gap == 0.0
    assert result.lower > 0.1
    assert result.lower <= value.lower + TOLERANCE
    optimum = packaged_optimum(name, horizon)
    assert result.lower - TOLERANCE <= optimum <= result.upper + TOLERANCE


def test_hold_rule_keeps_held_rows_on_the_free_move():
    """A held row leaves the free move only for a move whose L reaches its free_upper; other rows
    take the best L; the free move's L is raised to free_lower."""
    rng = np.random.default_rng(7)
    lower_q = rng.uniform(0, 1, size=(50, 3))
    strict_q, upper_q = lower_q.copy(), lower_q + 0.1
    free = rng.integers(0, 3, size=50)
    best = policy_choice(lower_q, strict_q, upper_q)
    assert (best != free).any()
    none = np.zeros(50, dtype=bool)
    move, _, _ = held_choice(lower_q, strict_q, upper_q, free, none, np.zeros(50), np.ones(50))
    assert np.array_equal(move, best)
    every = np.ones(50, dtype=bool)
    best_lower = lower_q.max(axis=1)
    move, _, _ = held_choice(lower_q, strict_q, upper_q, free, every, np.zeros(50), best_lower + 0.01)
    assert np.array_equal(move, free)
    move, _, _ = held_choice(lower_q, strict_q, upper_q, free, every, np.zeros(50), best_lower)
    assert np.array_equal(move, best)
    move, raised, _ = held_choice(lower_q, strict_q, upper_q, free, none, np.full(50, 2.0), np.ones(50))
    assert np.array_equal(move, free) and np.all(raised[np.arange(50), free] == 2.0)


# -- box enclosures: against brute-force vertex enumeration and a linear program ---------------

def _box_vertices(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Every vertex of {lo <= b <= hi, Σb = 1} by enumeration: n - 1 coordinates at a bound, the
    last one what makes the sum 1 (kept if it lies within its own bounds)."""
    n = lo.size
    found = []
    for free in range(n):
        others = [i for i in range(n) if i != free]
        for bits in range(2 ** (n - 1)):
            point = np.empty(n)
            for position, i in enumerate(others):
                point[i] = hi[i] if (bits >> position) & 1 else lo[i]
            point[free] = 1.0 - point[others].sum()
            if lo[free] - 1e-12 <= point[free] <= hi[free] + 1e-12:
                found.append(point)
    return np.array(found)


def _random_boxes(rng, count: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Boxes around random beliefs, from very narrow to a quarter of the simplex wide."""
    centre = rng.dirichlet(np.full(n, 0.7), size=count)
    width = 10.0 ** rng.uniform(-6, -0.6, size=(count, 1)) * rng.uniform(0.2, 1.0, size=(count, n))
    return np.maximum(centre - width, 0.0), np.minimum(centre + width, 1.0)


@pytest.mark.parametrize("dinkelbach_steps", [completion_value.DINKELBACH_STEPS, 1])
def test_box_image_is_the_exact_range_of_the_filter_over_the_box(pomdp, dinkelbach_steps, monkeypatch):
    """The image box equals, up to its margin, the per-coordinate range of f_o over the box's
    vertices found by enumeration (so it is tight as well as sound), on the iteration's path and,
    with one step (nothing settles), on the exhaustive greedy vertices."""
    monkeypatch.setattr(completion_value, "DINKELBACH_STEPS", dinkelbach_steps)
    symbols = observation_symbols(pomdp)
    rng = np.random.default_rng(17)
    lo, hi = _random_boxes(rng, 40, pomdp.n_trust)
    margin = completion_value.CORNER_MARGIN
    for o in range(symbols.n_symbols):
        image_lo, image_hi = completion_value.box_image(lo, hi, symbols, o)
        for row in range(lo.shape[0]):
            vertices = _box_vertices(lo[row], hi[row])
            images, probability = apply_symbol(vertices, symbols, o)
            images = images[probability > 0]
            assert np.all(image_lo[row] <= images.min(axis=0) + 1e-13)
            assert np.all(images.max(axis=0) <= image_hi[row] + 1e-13)
            assert np.all(image_lo[row] >= images.min(axis=0) - margin - 1e-12)
            assert np.all(image_hi[row] <= images.max(axis=0) + margin + 1e-12)


def test_box_image_encloses_the_images_of_points_inside(pomdp):
    """Random points of each box (mixtures of its vertices) map into the image box."""
    symbols = observation_symbols(pomdp)
    rng = np.random.default_rng(5)
    lo, hi = _random_boxes(rng, 30, pomdp.n_trust)
    for row in range(lo.shape[0]):
        vertices = _box_vertices(lo[row], hi[row])
        points = rng.dirichlet(np.full(len(vertices), 0.3), size=200) @ vertices
        for o in range(symbols.n_symbols):
            image_lo, image_hi = completion_value.box_image(lo[row:row + 1], hi[row:row + 1], symbols, o)
            images, probability = apply_symbol(points, symbols, o)
            images = images[probability > 0]
            assert np.all(images >= image_lo[0] - 1e-15) and np.all(images <= image_hi[0] + 1e-15)


def test_linear_range_is_the_linear_programs_optimum():
    """min and max of c·b over {lo <= b <= hi, Σb = 1} against scipy's linear programming (to its
    feasibility tolerance) and against the enumerated vertices (to rounding)."""
    from scipy.optimize import linprog

    rng = np.random.default_rng(3)
    n = 7
    lo, hi = _random_boxes(rng, 25, n)
    for row in range(lo.shape[0]):
        coeffs = rng.normal(size=n)
        low, high = completion_value.linear_range(lo[row:row + 1], hi[row:row + 1], coeffs)
        bounds = list(zip(lo[row], hi[row], strict=True))
        lp_min = linprog(coeffs, A_eq=np.ones((1, n)), b_eq=[1.0], bounds=bounds).fun
        lp_max = -linprog(-coeffs, A_eq=np.ones((1, n)), b_eq=[1.0], bounds=bounds).fun
        assert low[0] == pytest.approx(lp_min, abs=1e-6)
        assert high[0] == pytest.approx(lp_max, abs=1e-6)
        at_vertices = _box_vertices(lo[row], hi[row]) @ coeffs
        assert low[0] == pytest.approx(at_vertices.min(), abs=1e-12)
        assert high[0] == pytest.approx(at_vertices.max(), abs=1e-12)


@pytest.mark.slow
def test_bounds_on_a_long_route_are_tight_and_bracket_monte_carlo(driver):
    """The benchmark's 200-junction grid, 5 waypoint sets, 40 junctions from the start: the
    completion's bounds are within 0.01 of each other (the simplex {b >= l} enclosure that boxes
    replaced gave [0.833, 0.999] here) and bracket a Monte Carlo estimate of the completion's value
    (10 000 sampled observation sequences through the one filter and the labeller)."""
    from benchmarks.bench_synthesis_scaling import grid_or_paper_problem

    pomdp, spec = grid_or_paper_problem(200, 5, None)
    tables = build_product(pomdp, spec)
    symbols = observation_symbols(pomdp)
    task = state_only_task(pomdp.town, spec)
    route = FreeRoute.build(tables, free_completion(pomdp.town, spec).slot,
                            np.asarray(task.next_state, dtype=np.int64))
    belief = np.asarray(pomdp.initial_belief, dtype=float)
    horizon = 40
    starts = CompletionStarts(np.array([tables.start]), np.array([tables.initial_q]),
                              np.array([task.initial_state]), belief[None], np.array([horizon]))
    bounds = completion_bounds(tables, symbols, route, starts)
    assert bounds.upper[0] - bounds.lower[0] <= 0.01

    rng = np.random.default_rng(11)
    # 4 sigma at this count is 2e-3 of slack either side: a fifth of the bracket's allowed width
    count = 10_000
    beliefs = np.repeat(belief[None], count, 0)
    x = np.full(count, tables.start)
    q = np.full(count, tables.initial_q)
    p = np.full(count, task.initial_state)
    accepted = tables.accepting[q].copy()
    width = max(len(members) for members in symbols.by_incident)
    # the symbols each incident can show, padded with -1 to one width
    padded = np.array([list(members) + [-1] * (width - len(members)) for members in symbols.by_incident])
    for _ in range(horizon):
        going = ~accepted & ~tables.rejecting[q]
        x2, p2 = route.next_road[x, q, p], route.next_task[x, q, p]
        choices = padded[pomdp.road_incident[x2]]
        probability = np.where(choices >= 0, np.einsum("rn,rkn->rk", beliefs,
                                                        symbols.likelihood[np.maximum(choices, 0)]), 0.0)
        drawn = rng.random(count) * probability.sum(axis=1)
        pick = np.minimum((drawn[:, None] > np.cumsum(probability, axis=1)).sum(axis=1), width - 1)
        symbol = choices[np.arange(count), pick]
        posterior, _ = apply_symbol(beliefs, symbols, symbol)
        q2 = tables.step(q, x2, posterior)
        beliefs = np.where(going[:, None], posterior, beliefs)
        x, p, q = np.where(going, x2, x), np.where(going, p2, p), np.where(going, q2, q)
        accepted |= tables.accepting[q]
    estimate = accepted.mean()
    error = 4.0 * np.sqrt(max(estimate * (1 - estimate), 1e-4) / count)
    assert bounds.lower[0] - error <= estimate <= bounds.upper[0] + error


def test_fill_orders_are_every_lambdas_order_once_in_lexicographic_order():
    # the definition, one λ at a time: a descending order of a - λ d at every test point
    from trustroute.policies.synthesis.belief_cells import fill_orders

    rng = np.random.default_rng(7)
    for n in (2, 3, 7, 21):
        a, d = rng.random(n) * (rng.random(n) < 0.7), rng.random(n)
        d[-1] = d[0]                                  # a pair of equal slopes: no crossing
        points = np.sort(np.array([(a[i] - a[k]) / (d[i] - d[k]) for i in range(n)
                                   for k in range(i + 1, n) if d[i] != d[k]] + [0.0]))
        nudge = 1e-9 * np.maximum(np.abs(points), 1.0)
        tests = np.concatenate([points, points - nudge, points + nudge, (points[1:] + points[:-1]) / 2,
                                [points[0] - 1.0, points[-1] + 1.0]])
        expected = sorted({tuple(np.argsort(-(a - lam * d), kind="stable").tolist()) for lam in tests})
        assert fill_orders(a, d).tolist() == [list(order) for order in expected]
