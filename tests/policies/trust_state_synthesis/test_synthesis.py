"""Synthesis for specs with trust-state atoms against brute force, exact evaluation and Monte Carlo."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import trustroute
from tests.policies.trust_paths import optimum, policy_value
from tests.policies.trust_specs import random_problem
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import run_model_episode
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.belief.trust_state_relaxation import RELAXATION_MARGIN
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.evaluation.trust_state import (
    evaluate_joint,
    evaluate_joint_table,
    evaluate_joint_table_unbounded,
)
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.trust_state_table import JointTablePolicy
from trustroute.policies.synthesis.population import PopulationSynthesis
from trustroute.policies.synthesis.result import SynthesisResult
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesize_spec import synthesize_spec
from trustroute.policies.trust_state_synthesis import synthesis
from trustroute.policies.trust_state_synthesis.search import joint_bounds

TOLERANCE = 1e-9


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["trust", "belief", "mixed"]),
       horizon=st.integers(1, 3))
def test_bounds_bracket_the_brute_force_optimum_and_lower_is_the_policys_value(driver, seed, kind,
                                                                               horizon):
    rng = np.random.default_rng(seed)
    pomdp, spec = random_problem(rng, driver, kind)
    reference = optimum(pomdp, spec, horizon)
    result = synthesize_spec(pomdp, spec, SynthesisSettings(horizon=horizon, time_limit=20))
    assert result.lower - TOLERANCE <= reference <= result.upper + TOLERANCE
    # The returned policy's value by brute force over trust paths (its joint belief computed
    # there from the paths, not by the filter): L is exactly that value (joint), at most it (plain).
    value = policy_value(pomdp, spec, result.policy, horizon)
    if spec.uses_trust_atoms:
        assert isinstance(result.policy, JointTablePolicy)
        assert value == pytest.approx(result.lower, abs=TOLERANCE)
    else:
        assert value >= result.lower - TOLERANCE
    assert value <= reference + TOLERANCE


@pytest.mark.slow
def test_unbounded_bounds_bracket_the_bounded_optimum_and_lower_is_the_policys_value(driver):
    pomdp, spec = random_problem(np.random.default_rng(5), driver, "trust")
    reference = optimum(pomdp, spec, 3)
    # A work limit (policies/work_clock.py), not the wall clock: the unbounded search does not
    # converge here and would run to any time limit; these units give L > 0, the same on any machine.
    unbounded = synthesize_spec(pomdp, spec, SynthesisSettings(horizon=None, time_limit=900,
                                                               work_limit=300_000))
    # Pr_max of the unbounded objective is at least the bounded optimum.
    assert unbounded.upper >= reference - TOLERANCE
    assert 0 < unbounded.lower <= unbounded.upper + TOLERANCE
    cap = unbounded.stats.policy_search_horizon
    # L is a certified lower end of the policy's value over unbounded time, which is at least
    # its value within its search horizon: the pruned tree unfolding's lower end there is below
    # the unbounded upper end.
    exact = evaluate_joint(pomdp, spec, unbounded.policy,
                           EvaluationSettings(fallback_after=None, max_junctions=cap, max_nodes=2_000))
    value = unbounded.stats.policy_value
    # L is the evaluation's lower end rounded down (policies/synthesis/rounding.py)
    assert unbounded.lower < value.lower and value.lower - unbounded.lower < 1e-10
    assert value.stopped_by is not None
    assert exact.lower <= value.upper + TOLERANCE
    assert unbounded.stats.to_dict()["policy_value"]["unbounded"] is True


def test_merged_evaluation_equals_the_tree_unfolding_of_evaluate_joint(pomdp):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    result = synthesize_spec(pomdp, spec, SynthesisSettings(horizon=8, time_limit=20))
    assert result.gap <= 1e-3
    for cap in (8, 12):
        tree = evaluate_joint(pomdp, spec, result.policy,
                              EvaluationSettings(fallback_after=None, max_junctions=cap))
        merged = evaluate_joint_table(pomdp, spec, result.policy, cap)
        assert tree.gap == 0.0 and merged.lower == merged.upper and merged.stopped == "convergence"
        assert merged.lower == pytest.approx(tree.lower, abs=1e-12)
    assert result.lower == pytest.approx(evaluate_joint(pomdp, spec, result.policy,
                                                        EvaluationSettings(fallback_after=None,
                                                                           max_junctions=8)).lower, abs=1e-12)


def test_a_time_limit_shorter_than_the_first_round_stops_it_with_sound_bounds(pomdp):
    """The deadline is checked before the first level is expanded: a limit that has passed by then
    leaves the root a leaf (one node), and the bounds still bracket the exact optimum."""
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    exact = joint_bounds(pomdp, spec, depth=0, horizon=8)
    assert exact.cut_nodes == 0 and exact.nodes > 1000
    result = synthesize_spec(pomdp, spec, SynthesisSettings(horizon=8, time_limit=1e-6))
    assert [run.bounds.nodes for run in result.stats.runs] == [1]
    assert result.lower - TOLERANCE <= exact.lower <= result.upper + TOLERANCE
    assert result.upper < 1.0
    # the statistics' JSON ("stats" of trustroute synth --json)
    stats = result.stats.to_dict()
    assert list(stats) == ["method", "belief_rule", "converged", "stopped", "tau", "runs", "policy_rows",
                           "policy_search_horizon", "search_lower", "policy_value"]
    assert stats["stopped"] == "deadline"
    assert list(stats["runs"][0]) == ["search", "max_nodes", *result.stats.runs[0].bounds.to_dict(),
                                      "policy_lower", "policy_upper"]
    assert stats["runs"][0]["nodes"] == 1
    assert stats["policy_value"] == {"lower": result.lower, "upper": result.stats.policy_value.upper,
                                     "max_junctions": 8}


@pytest.mark.slow
def test_monte_carlo_of_the_returned_policy_with_hidden_trust_agrees_with_lower(town, driver, pomdp):
    """Episodes through the episode tracker (the joint belief tracked online, the driver's trust
    hidden from the AV, satisfaction read on the true trust) agree with L within 4 SE."""
    spec = load_spec("specs/phi1_trust.toml", town)
    horizon = 10
    result = synthesize_spec(pomdp, spec, SynthesisSettings(horizon=horizon, time_limit=20))
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec, junction_cap=horizon,
                         fallback_after=None)
    rng = np.random.default_rng(20261201)
    episodes = 600
    satisfied = np.zeros(episodes, dtype=bool)
    for n in range(episodes):
        synthetic = SyntheticDriver(driver, np.random.default_rng(rng.integers(2**63)))
        record = run_model_episode(setup, result.policy, synthetic, f"e{n}", n)
        satisfied[n] = record.summary["satisfied"]
    p = result.lower
    se = max(np.sqrt(p * (1 - p) / episodes), 1.0 / episodes)
    assert abs(satisfied.mean() - p) <= 4 * se + result.gap, (satisfied.mean(), p, se)


WORK = 5_000_000


def _synthesized(spec: str, horizon: int | None, tau: float = 1e-3) -> SynthesisResult:
    """`trustroute.synthesize` under a work limit far beyond what the runs below take (about 0.1 s
    each), so a stop said to be the work or time limit would be untrue."""
    result = trustroute.synthesize(spec, horizon=horizon, tau=tau, time_limit=600, work_limit=WORK)
    assert isinstance(result, SynthesisResult)
    return result


def test_a_synthesis_exact_but_for_its_rounding_margin_says_so(capsys, tmp_path):
    """Within a horizon the first round's search is complete and the policy's value exact: the gap is
    the search's 1e-12 allowance for rounding, above a τ of 1e-15. The run ends in a fraction of a
    second and says "rounding margin" (not its time or work limit), in the API, in --json and in the
    summary."""
    from tests.cli import cli_json, run_cli

    result = _synthesized("phi1_trust", 6, tau=1e-15)
    assert [run.bounds.cut_nodes for run in result.stats.runs] == [0]
    assert 0 < result.upper - result.lower <= 2 * RELAXATION_MARGIN
    assert result.stopped_by == "rounding margin"
    assert result.stats.stopped == "rounding margin" and result.stats.policy_value.stopped == "convergence"
    command = ["synth", "phi1_trust", "--horizon", "6", "--tau", "1e-15", "--time-limit", "600"]
    payload = cli_json(capsys, *command, "--out", str(tmp_path / "a.json"))
    assert payload["stopped_by"] == payload["stats"]["stopped"] == "rounding margin"
    code, out, err = run_cli(capsys, *command, "--out", str(tmp_path / "b.json"))
    assert code == 0, err
    assert "allowance for rounding" in out and "would not tighten" in out


def test_a_population_bayes_synthesis_says_the_cap_of_its_one_trust_state_run():
    """The Bayes objective's bounds over driver types are its one trust-state synthesis' (on the
    lifted model): exact but for the rounding margin, it says so too."""
    found = trustroute.synthesize("phi1_trust", horizon=6, tau=1e-15, time_limit=600, work_limit=WORK,
                                  population="driver_population_three_types", objective="bayes")
    assert isinstance(found, PopulationSynthesis)
    assert found.result.stopped_by == "rounding margin"
    assert found.result.stats.stopped == "rounding margin"


def test_the_search_at_its_largest_nodes_per_level_says_node_cap(monkeypatch):
    """The rounds grow the nodes per level up to MAX_NODES: with MAX_NODES the first round's, a
    first round that cut nodes ends the rounds with time to spare, at "node cap"."""
    monkeypatch.setattr(synthesis, "MAX_NODES", synthesis.FIRST_NODES)
    result = _synthesized("phi1_trust", 10, tau=1e-13)
    assert len(result.stats.runs) == 1 and result.stats.runs[0].bounds.cut_nodes > 0
    assert result.upper - result.lower > 1e-13
    assert result.stopped_by == "node cap"
    assert result.stats.stopped == "node cap"


@pytest.fixture
def shallow(monkeypatch):
    """The unbounded synthesis with depth-3 searches and policy (complete in their first round on
    the paper's town) and given limits of the evaluation of the policy over unbounded time (its
    nodes per level are the synthesis' EVALUATION_NODES)."""
    monkeypatch.setattr(synthesis, "UNBOUNDED_DEPTHS", (3,))
    monkeypatch.setattr(synthesis, "UNBOUNDED_POLICY_HORIZONS", (3,))

    def evaluated_with(max_nodes: int = synthesis.EVALUATION_NODES, **limits) -> None:
        monkeypatch.setattr(synthesis, "EVALUATION_NODES", max_nodes)
        monkeypatch.setattr(synthesis, "evaluate_joint_table_unbounded",
                            functools.partial(evaluate_joint_table_unbounded, **limits))
    return evaluated_with


@pytest.mark.parametrize(("limits", "value_stop", "stop"), [
    # the evaluation resolves its open mass, but dropped more than its tolerance
    ({"max_nodes": 3}, "node cap", "node cap"),
    # the evaluation stops at its junction cap with live mass open
    ({"max_junctions": 4}, "junction cap", "junction cap"),
    # the evaluation converges (at a tolerance of 0.5): U is what the searches' depth left
    ({"tolerance": 0.5}, "convergence", "depth cap"),
])
def test_an_unbounded_synthesis_says_which_cap_ended_it(shallow, limits, value_stop, stop):
    """Every search complete at depth 3, the policy's evaluation ended by its own cap or converged:
    the run ends in a fraction of its work limit, and both the policy's value and the synthesis say
    which cap ended them, not the time or work limit."""
    shallow(**limits)
    result = _synthesized("phi1_trust", None)
    assert [run.bounds.cut_nodes for run in result.stats.runs] == [0, 0]
    value = result.stats.to_dict()["policy_value"]
    assert value["unbounded"] is True and value["stopped_by"] == value_stop
    assert result.upper - result.lower > 1e-3
    assert result.stopped_by == stop
    assert result.stats.stopped == stop
