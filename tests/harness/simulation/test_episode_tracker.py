"""EpisodeTracker: the AV's side of an episode, checked against independent computations."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from tests.harness.helpers import SPECS, FixedRoute
from trustroute.core.dataset import ROADS_SCHEMA
from trustroute.harness.simulation.episode_tracker import DrivenRoad, EpisodeSetup, EpisodeTracker
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import baseline_route, trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy


@pytest.fixture(scope="module")
def phi1(town):
    return load_spec(SPECS / "phi1.toml", town)


@pytest.fixture(scope="module")
def phi1_strict(town):
    return load_spec(SPECS / "phi1_strict.toml", town)


class LoopPolicy(RoutingPolicy):
    """Circles F-G-I-H-F for ever (never finished): exercises the cap and the fallback."""

    name = "loop"
    ring = {"F": "G", "G": "I", "I": "H", "H": "F"}

    def next_junction(self, context):
        at = context.road.split("-")[1]
        return self.ring.get(at, "F")


def model_episode(setup, policy, driver, episode_id="e"):
    """The model engine's loop in miniature: observations drawn from the synthetic driver."""
    tracker = EpisodeTracker(setup, policy, episode_id, initial_trust=driver.trust)
    t = 0.0
    while (junction := tracker.next_junction()) is not None:
        road = setup.town.successor(tracker.road, junction)
        incident = setup.town.incident(road)
        took_over = driver.decides_takeover(incident)
        performance = driver.performance(incident)
        before = driver.trust
        after = driver.move_trust(incident, took_over, performance)
        reported = driver.report_trust() if tracker.should_report() else None
        tracker.record_road(DrivenRoad(road, incident, took_over, performance, before, after, reported,
                                       t, t + 1))
        t += 1
    return tracker


def test_belief_and_dfa_follow_the_filter_step_by_step(town, driver, pomdp, phi1):
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1)
    tracker = EpisodeTracker(setup, trust_free_policy(town, phi1), "e", initial_trust=3)
    dfa = build_dfa(phi1)
    labeller = Labeller(phi1, dfa, town)
    belief = np.asarray(driver.initial_belief, dtype=float)
    q = int(labeller.step(np.array([dfa.initial]), np.array([town.state_index(phi1.start)]), belief[None])[0])
    assert tracker.dfa_state == q
    observations = [(True, "succ"), (False, "succ"), (True, "succ"), (False, "succ"), (False, "succ")]
    for took_over, performance in observations:
        junction = tracker.next_junction()
        assert junction is not None and tracker.next_junction() == junction  # idempotent at a road
        road = town.successor(tracker.road, junction)
        incident = town.incident(road)
        took_over = took_over and incident != "none"   # no takeover without an incident (probability 0)
        tracker.record_road(DrivenRoad(road, incident, took_over, performance, 3, 3, None, 0.0, 1.0))
        belief, _ = pomdp.belief_update(belief, driver.incident_index(incident), int(took_over), 0)
        belief = belief[0]
        q = int(labeller.step(np.array([q]), np.array([town.state_index(road)]), belief[None])[0])
        np.testing.assert_allclose(tracker.belief, belief, atol=1e-12)
        assert tracker.dfa_state == q
    frame = tracker.roads_frame()
    assert tuple(frame.columns) == tuple(ROADS_SCHEMA.names)
    assert list(frame["index"]) == list(range(len(observations) + 1))
    assert frame.loc[0, "incident"] == "none" and frame["reported_trust"].isna().all()
    assert frame.loc[0, ["takeover", "performance"]].isna().all()
    np.testing.assert_allclose(frame.iloc[-1]["belief_after"], belief)
    assert frame["action"].iloc[:-1].notna().all() and pd.isna(frame["action"].iloc[-1])


def test_memoised_steps_give_the_computed_floats(town, driver, pomdp, phi1):
    """Trackers over observation sequences that share their start but differ in takeover and
    performance, run after each other so later ones take steps from the memo: every belief is
    bit-identical to the direct filter's and every DFA state to the labeller's. A memo key that
    ignored the takeover or the performance would hand the second sequence the first one's belief."""
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1)
    assert not setup.model.updates   # a new setup's memo starts empty
    dfa = build_dfa(phi1)
    labeller = Labeller(phi1, dfa, town)
    # The same route; up to its first incident the priors agree, then the sequences differ in one
    # of takeover and performance only.
    sequences = [[(True, "succ")] * 5, [(False, "succ")] * 5, [(True, "fail")] * 5]
    for observations in sequences + sequences:
        tracker = EpisodeTracker(setup, trust_free_policy(town, phi1), "e", initial_trust=3)
        belief = np.asarray(driver.initial_belief, dtype=float)
        q = int(labeller.step(np.array([dfa.initial]), np.array([town.state_index(phi1.start)]),
                              belief[None])[0])
        for took_over, performance in observations:
            road = town.successor(tracker.road, tracker.next_junction())
            incident = town.incident(road)
            took_over = took_over and incident != "none"
            tracker.record_road(DrivenRoad(road, incident, took_over, performance, 3, 3, None, 0.0, 1.0))
            posterior, _ = pomdp.belief_update(belief, driver.incident_index(incident), int(took_over),
                                               {"succ": 0, "fail": 1}[performance])
            belief = posterior[0] if posterior[0].sum() > 0 else belief
            q = int(labeller.step(np.array([q]), np.array([town.state_index(road)]), belief[None])[0])
            assert tracker.belief.tobytes() == belief.tobytes()
            assert tracker.dfa_state == q
    assert len(setup.model.updates) > 0


def test_free_policy_drives_the_baseline_route(town, driver, phi1):
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1)
    always_trusting = SyntheticDriver(driver, np.random.default_rng(0), initial_trust=7)
    tracker = model_episode(setup, trust_free_policy(town, phi1), always_trusting)
    assert tracker.route == baseline_route(town, phi1)
    assert tracker.end_reason in ("accepted", "destination")


def test_monte_carlo_matches_exact_evaluation(town, driver, pomdp, phi1):
    """Satisfaction frequency of tracker episodes vs the exact tree evaluation (fallback 20)."""
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1)
    policy = trust_free_policy(town, phi1)
    exact = evaluate(pomdp, phi1, policy, EvaluationSettings(fallback_after=20))
    rng = np.random.default_rng(12345)
    n = 1500
    satisfied = 0
    final_trust = 0.0
    for i in range(n):
        tracker = model_episode(setup, policy, SyntheticDriver(driver, rng), f"e{i}")
        summary = tracker.summary(wall_seconds=0.0, sim_seconds=0.0)
        satisfied += summary["satisfied"]
        final_trust += summary["final_trust"]
    p = exact.satisfaction_probability
    assert abs(satisfied / n - p) < 4 * math.sqrt(p * (1 - p) / n) + 1e-9
    assert abs(final_trust / n - exact.expected_final_trust) < 0.15


@pytest.mark.slow
def test_trust_state_spec_with_driver_types_matches_the_exact_per_type_values(town):
    """A spec testing the hidden trust, a population of three types: the tracker follows
    J((type, trust), q) and reads satisfaction on the driver's true trust; per type, the
    frequency of satisfied episodes agrees with the exact per-type value of the lifted unfolding."""
    from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
    from trustroute.policies.belief.problem import TRUST_STATE, problem
    from trustroute.policies.evaluation.trust_state import evaluate_joint_by_type

    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    found = problem(town, population, load_spec(SPECS / "phi1_trust.toml", town))
    assert found.case == TRUST_STATE
    setup = EpisodeSetup(town=town, driver_model=found.driver, spec=found.spec, junction_cap=14,
                         fallback_after=None)
    policy = trust_free_policy(town, found.spec)
    _, per_type = evaluate_joint_by_type(found.pomdp, found.spec, policy,
                                         EvaluationSettings(fallback_after=None, max_junctions=14))
    rng = np.random.default_rng(2024)
    n = 600
    for kind, (lower, upper) in zip(population.types, per_type, strict=True):
        assert upper - lower < 1e-9
        satisfied = sum(model_episode(setup, policy, SyntheticDriver(kind.model, rng), f"e{i}").satisfied
                        for i in range(n))
        assert abs(satisfied / n - lower) < 4 * math.sqrt(max(lower * (1 - lower), 1e-4) / n) + 1e-9


def test_rejected_end(town, driver, phi1_strict):
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1_strict)
    tracker = EpisodeTracker(setup, FixedRoute(("E-A", "A-B", "B-C", "C-D")), "e", initial_trust=1)
    # A takeover at the pedestrian on A-B pushes the belief to low trust before v1: rejected.
    while tracker.end_reason is None:
        junction = tracker.next_junction()
        if junction is None:
            break
        road = town.successor(tracker.road, junction)
        tracker.record_road(DrivenRoad(road, town.incident(road), True, "succ", 1, 1, 1, 0.0, 0.0))
    assert tracker.end_reason == "rejected"
    assert bool(tracker.dfa.rejecting[tracker.dfa_state])
    assert tracker.next_junction() is None


def test_cap_and_fallback(town, driver, phi1):
    capped = EpisodeTracker(EpisodeSetup(town=town, driver_model=driver, spec=phi1, junction_cap=5,
                                         fallback_after=None), LoopPolicy(), "cap", initial_trust=4)
    standstill = SyntheticDriver(driver, np.random.default_rng(1), initial_trust=4)
    while (junction := capped.next_junction()) is not None:
        road = town.successor(capped.road, junction)
        capped.record_road(DrivenRoad(road, town.incident(road), False, "succ", standstill.trust,
                                      standstill.trust, None, 0.0, 0.0))
    assert capped.end_reason == "cap" and capped.junctions == 5
    assert not capped.fallback_fired

    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1, fallback_after=3)
    tracker = model_episode(setup, LoopPolicy(), SyntheticDriver(driver, np.random.default_rng(2)))
    frame = tracker.roads_frame()
    assert tracker.fallback_fired and tracker.fallback_junction == 3
    assert not frame["fallback"].iloc[:3].any() and frame["fallback"].iloc[3]
    assert tracker.end_reason in ("accepted", "destination")


def test_report_every(town, driver, phi1):
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1, report_every=2)
    tracker = model_episode(setup, trust_free_policy(town, phi1),
                            SyntheticDriver(driver, np.random.default_rng(3), initial_trust=7))
    reported = tracker.roads_frame()["reported_trust"].tolist()
    assert all((not pd.isna(r) and r >= 1) == (i % 2 == 0 and i > 0) for i, r in enumerate(reported))


def test_illegal_and_out_of_order_roads_are_refused(town, driver, phi1):
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1)
    tracker = EpisodeTracker(setup, trust_free_policy(town, phi1), "e", initial_trust=4)
    with pytest.raises(ValueError, match="before next_junction"):
        tracker.record_road(DrivenRoad("A-F", "none", False, "succ", 4, 4, None, 0.0, 0.0))
    tracker.next_junction()
    with pytest.raises(ValueError, match="policy chose"):
        tracker.record_road(DrivenRoad("A-B", "pedestrian", False, "succ", 4, 4, None, 0.0, 0.0))
    with pytest.raises(ValueError, match="performance"):
        tracker.record_road(DrivenRoad(tracker.expected_road(), "none", False, "ok", 4, 4, None, 0.0, 0.0))


def test_a_label_floats_cannot_decide_is_read_as_synthesis_and_evaluate_read_it(town, driver, pomdp):
    """phi1_strict with the lowtrust offset written 0.2857142857142857 (float 2/7): the uniform
    prior's exact 2/7 is above it, while the float c·b̂ equals it. The tracker, the model engine,
    the search's root and `evaluate` all read lowtrust true (policies/belief/exact_labels.py):
    rejected at once."""
    from trustroute.harness.simulation.model_engine import simulate_batch
    from trustroute.policies.belief.product_mdp import build_product
    from trustroute.policies.logic.spec import spec_from_text

    text = (SPECS / "phi1_strict.toml").read_text()
    assert "offset = 0.3\n" in text
    spec = spec_from_text(text.replace("offset = 0.3\n", "offset = 0.2857142857142857\n"),
                          "<phi1_strict 2/7>", town)
    dfa = build_dfa(spec)
    start = np.array([town.state_index(spec.start)])
    prior = np.asarray(driver.initial_belief, dtype=float)[None, :]
    float_reading = int(Labeller(spec, dfa, town).step(np.array([dfa.initial]), start, prior)[0])
    exact_reading = build_product(pomdp, spec).initial_q
    assert float_reading != exact_reading and bool(dfa.rejecting[exact_reading])
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    tracker = EpisodeTracker(setup, trust_free_policy(town, spec), "e", initial_trust=4)
    assert tracker.dfa_state == exact_reading
    assert tracker.end_reason == "rejected"
    batch = simulate_batch(setup, trust_free_policy(town, spec), 20, np.random.default_rng(0))
    assert (batch.end_reason == "rejected").all()
    free = trust_free_policy(town, spec)
    assert evaluate(pomdp, spec, free, EvaluationSettings(fallback_after=None)).lower == 0.0


def test_the_fallback_never_takes_over_from_the_trust_free_policy(town, driver, phi1, pomdp):
    """The trust-free policy drives the shortest completion the rule switches to: past the rule's
    junction it drives on as without the rule, and neither the episode nor the exact evaluation
    counts it as fallen back; a policy that drives otherwise still is."""
    free = trust_free_policy(town, phi1)
    routes = {}
    for after in (None, 2):
        setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1, fallback_after=after)
        tracker = model_episode(setup, free, SyntheticDriver(driver, np.random.default_rng(5)))
        assert tracker.junctions > 2 and not tracker.fallback_fired
        assert not tracker.roads_frame()["fallback"].any()
        routes[after] = tracker.roads_frame()["directed_road"].tolist()
    assert routes[2] == routes[None]
    exact = evaluate(pomdp, phi1, free, EvaluationSettings(fallback_after=2))
    assert exact.fallback_probability == 0.0
    assert exact.satisfaction_probability == evaluate(
        pomdp, phi1, free, EvaluationSettings(fallback_after=None)).satisfaction_probability
    from trustroute.policies.routing.fallback import with_fallback

    assert not with_fallback(free, town, phi1, after=2).takes_over
    other = trust_free_policy(town, load_spec(SPECS / "phi2.toml", town))   # another task's moves
    assert with_fallback(other, town, phi1, after=2).takes_over
    looping = evaluate(pomdp, phi1, LoopPolicy(), EvaluationSettings(fallback_after=2))
    assert looping.fallback_probability == pytest.approx(1.0, abs=1e-12)
