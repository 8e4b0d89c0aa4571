"""The event graph: macro moves are shortest quiet paths, and the compressed search equals the plain one.

Random small towns get `none` on about half their roads (so that compression removes roads); the
default driver model has the one quiet incident (`none`: one observation, identity update). With a
tiny tau both searches close their gap, so L and U must agree to float rounding, bracket the
exhaustive optimum, and the compressed policy, evaluated junction by junction, is worth L.
"""

from __future__ import annotations

import dataclasses
from collections import deque

import numpy as np
import pytest

from tests.policies.synthesis.test_synthesis_random import random_spec, random_town
from trustroute.networks.town import INCIDENT_TYPES, NO_INCIDENT
from trustroute.policies.belief.product_mdp import build_product
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import free_completion, state_only_task
from trustroute.policies.synthesis.belief_cells import observation_symbols
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.event_graph import EventGraph
from trustroute.policies.synthesis.exact_search import exact_optimum
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesis.upper_bound import acceptance_distance

TOLERANCE = 1e-12


def quiet_town(rng: np.random.Generator):
    """A random small town with `none` on about half of its directed roads."""
    town = random_town(rng)
    incidents = {road: NO_INCIDENT if rng.random() < 0.5 else str(rng.choice(INCIDENT_TYPES[:-1]))
                 for road in town.states}
    return dataclasses.replace(town, incidents=incidents)


def _event_graph(pomdp, spec, mode: str = "full") -> EventGraph:
    tables = build_product(pomdp, spec)
    return EventGraph(tables, observation_symbols(pomdp), state_only_task(pomdp.town, spec),
                      chains_only=mode == "chains", free_slot=free_completion(pomdp.town, spec).slot)


def _shortest_quiet_lengths(events: EventGraph, x: int, q: int, p: int) -> dict[int, int]:
    """Independent reference: breadth-first search over (road, junctions) pairs, every path of
    quiet roads from x, recording the fewest junctions to each event road."""
    event = events.event_roads(q, p)
    best: dict[int, int] = {}
    queue = deque([(x, 0)])
    visited = set()
    while queue:
        road, steps = queue.popleft()
        for s in events.successors[road]:
            s = int(s)
            if s < 0:
                continue
            if event[s]:
                best[s] = min(best.get(s, steps + 1), steps + 1)
            elif s not in visited:
                visited.add(s)
                queue.append((s, steps + 1))
    return best


@pytest.mark.parametrize("mode", ["full", "chains"])
@pytest.mark.parametrize("seed", range(8))
def test_macro_moves_are_the_shortest_quiet_paths(driver, seed, mode):
    rng = np.random.default_rng(500 + seed)
    town = quiet_town(rng)
    pomdp = build_pomdp(town, driver)
    spec = random_spec(rng, town, pomdp.initial_belief)
    events = _event_graph(pomdp, spec, mode)
    tables = build_product(pomdp, spec)
    task = state_only_task(town, spec)
    completion = free_completion(town, spec)
    live = np.flatnonzero(~(tables.accepting | tables.rejecting)).tolist()   # the searched states
    for x in range(tables.n_x):
        for q in live:
            for p in range(task.dfa.n_states):
                moves = events.moves(x, q, p)
                event = events.event_roads(q, p)
                expected = _shortest_quiet_lengths(events, x, q, p)
                minimum: dict[int, int] = {}
                for e, d in zip(moves.target.tolist(), moves.length.tolist(), strict=True):
                    if e >= 0:
                        minimum[e] = min(minimum.get(e, d), d)
                assert minimum == expected          # every event road, each by a shortest path
                if mode == "full":                  # one move per target (and the free one)
                    others = [e for a, e in enumerate(moves.target.tolist()) if a != moves.free]
                    assert len(set(others)) == len(others)
                else:                               # one move per junction
                    assert moves.count == (tables.successors[x] >= 0).sum()
                assert moves.count <= events.width
                for a in range(moves.count):
                    route, target = moves.path[a], int(moves.target[a])
                    assert route[0][0] == x and len(route) == moves.length[a]
                    for (road, slot), (nxt, _) in zip(route, [*route[1:], (target, 0)], strict=True):
                        if nxt >= 0:
                            assert tables.successors[road, slot] == nxt
                    assert not event[[road for road, _ in route[1:]]].any()     # quiet in between
                # the free move follows the free completion's junctions (the policy's fallback)
                for road, slot in moves.path[moves.free]:
                    assert slot == completion.slot[road, q, p]


@pytest.fixture(scope="module")
def references():
    """The plain search and the brute-force optimum per problem, each computed once: both
    compression modes compare against the same ones (keyed by the problem's seed or name, the
    spec's text and the horizon)."""
    return {}


def _reference(references, key, pomdp, spec, horizon: int, name: str):
    key = (key, repr(spec), horizon, name)
    if key not in references:
        references[key] = (
            synthesize(pomdp, spec,
                       SynthesisSettings(tau=TOLERANCE, horizon=horizon, time_limit=60, compress="off"))
            if name == "plain" else exact_optimum(pomdp, spec, horizon))
    return references[key]


def _compare(pomdp, spec, horizon: int, mode: str, references, key, optimum_of=None) -> bool | None:
    """Compressed and plain search agree, bracket the optimum, and the policy is worth L. Returns
    whether the search was compressed (None: answered by graph distance, no search)."""
    plain = _reference(references, key, pomdp, spec, horizon, "plain")
    packed = synthesize(pomdp, spec,
                        SynthesisSettings(tau=TOLERANCE, horizon=horizon, time_limit=60, compress=mode))
    run = packed.stats.runs[0]
    if not run.nodes:
        assert plain.upper == packed.upper == 0.0
        return None
    if run.compressed is False:      # nothing to pass through: exactly the plain search
        assert (packed.lower, packed.upper) == (plain.lower, plain.upper)
        return False
    assert packed.lower == pytest.approx(plain.lower, abs=TOLERANCE)
    assert packed.upper == pytest.approx(plain.upper, abs=TOLERANCE)
    optimum = optimum_of() if optimum_of else _reference(references, key, pomdp, spec, horizon, "optimum")
    assert packed.lower - TOLERANCE <= optimum <= packed.upper + TOLERANCE
    online = evaluate(pomdp, spec, packed.policy,
                      EvaluationSettings(fallback_after=None, max_junctions=horizon))
    assert online.lower >= packed.lower - TOLERANCE
    if run.row_conflicts == 0:
        assert online.lower == pytest.approx(packed.lower, abs=TOLERANCE)
    return True


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["full", "chains"])
@pytest.mark.parametrize("seed", range(10))
def test_compressed_search_equals_plain_search_on_random_towns(driver, references, seed, mode):
    rng = np.random.default_rng(700 + seed)
    town = quiet_town(rng)
    pomdp = build_pomdp(town, driver)
    # `(!high) U ...` makes every road an event while it waits (a true `high` rejects): drawn
    # again until some road is quiet, so that compression removes something, and acceptance is
    # possible within 6 junctions (else the graph distance answers without a search)
    for _ in range(40):
        spec = random_spec(rng, town, pomdp.initial_belief)
        tables = build_product(pomdp, spec)
        if (_event_graph(pomdp, spec, mode).compresses
                and acceptance_distance(tables)[tables.start, tables.initial_q] <= 6):
            break
    assert _event_graph(pomdp, spec, mode).compresses
    assert _compare(pomdp, spec, int(rng.integers(6, 8)), mode, references, seed) is True


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["full", "chains"])
@pytest.mark.parametrize("name", ["phi1", "phi2", "phi1_strict", "phi2_strict"])
def test_compressed_search_equals_plain_search_on_the_paper_town(pomdp, references, packaged_optimum, name,
                                                                 mode):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    # the session's optimum: test_synthesis.py and test_completion_value.py ask for the same ones
    assert _compare(pomdp, spec, 8, mode, references, name, lambda: packaged_optimum(name, 8)) is not None


def test_no_quiet_road_gives_the_plain_search(driver):
    """Without `none` roads the macro moves are the junctions: bounds and node counts identical."""
    searched = 0
    for seed in range(6):
        rng = np.random.default_rng(40 + seed)
        town = random_town(rng)
        town = dataclasses.replace(town, incidents={road: "truck" for road in town.states})
        pomdp = build_pomdp(town, driver)
        spec = random_spec(rng, town, pomdp.initial_belief)
        assert not _event_graph(pomdp, spec, "full").compresses
        runs = [synthesize(pomdp, spec, SynthesisSettings(tau=1e-3, horizon=6, time_limit=60, compress=c))
                for c in ("off", "chains", "full")]
        for run in runs[1:]:
            assert run.lower == runs[0].lower and run.upper == runs[0].upper
            assert run.stats.runs[0].nodes == runs[0].stats.runs[0].nodes
            assert run.policy.table.rows == runs[0].policy.table.rows
        if runs[0].stats.runs[0].nodes:          # searched (not answered by graph distance)
            searched += 1
            assert all(run.stats.runs[0].compressed is False for run in runs[1:])
    assert searched >= 3


def test_quiet_roads_leave_the_belief_bit_for_bit(pomdp, driver):
    """The one filter on `none`: the same belief and probability exactly 1 (so a quiet road changes
    nothing but the clock), where renormalising would have moved the uniform prior."""
    none = driver.incident_index(NO_INCIDENT)
    belief = np.asarray(pomdp.initial_belief, dtype=float)
    assert belief.sum() != 1.0          # the case that drifted: 7 × fl(1/7)
    after, probability = pomdp.belief_update(belief, none, 0, 0)
    assert after[0].tobytes() == belief.tobytes()
    assert probability[0] == 1.0
    assert pomdp.preserves_belief("bayes")[none, 0, 0]
    assert not pomdp.preserves_belief("bayes")[driver.incident_index("obstacle")].any()
