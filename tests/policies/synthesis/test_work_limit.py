"""A work limit stops a synthesis after the same work whatever the clock says (policies/work_clock.py):
the same inputs under a clock that drags (every reading later than the last by a good share of a
second) give the same bounds, runs and policy; the wall-clock time limit still stops a run."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import pytest

import trustroute
from trustroute.core import defaults

POPULATION = "driver_population_three_types"
SLOW = defaults.MAX_TIME_LIMIT    # the longest limit a door takes: never binds, but for a dragging clock
# The time limit a dragging clock reaches (each reading 0.05 s after the last) long before φ1 at
# H = 10 converges, which takes about 1 s without it.
DRAGGED_LIMIT = 0.5


def _dragging_clock(step: float = 0.02):
    """time.perf_counter() that runs fast: each reading `step` seconds after the last one."""
    real = time.perf_counter
    readings = [0]

    def perf_counter() -> float:
        readings[0] += 1
        return real() + step * readings[0]

    return perf_counter


def _slow_clock(factor: float = 20.0):
    """time.perf_counter() of a machine `factor` times slower (or as loaded): every interval from
    now on reads `factor` times as long."""
    real = time.perf_counter
    start = real()
    return lambda: start + factor * (real() - start)


TIMED = ("seconds", "created")   # what a policy file and the statistics say of the time taken


def _untimed(value):
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if not any(t in k for t in TIMED)}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def _policy_file(path: Path) -> tuple[dict, dict[str, bytes]]:
    arrays = np.load(path.with_suffix(".npz"))
    document = {k: v for k, v in json.loads(path.read_text()).items() if k != "arrays"}   # (its own name)
    return _untimed(document), {name: arrays[name].tobytes() for name in arrays.files}


@pytest.mark.parametrize(("spec", "horizon", "work_limit"), [
    ("phi1", 10, 20_000),            # the bounded belief-MDP search
    ("phi1", None, 100_000),         # the unbounded one: end components, growing horizons
    # the trust-state search and its unbounded evaluation (about 10 s a run)
    pytest.param("phi1_trust", None, 1_000_000, marks=pytest.mark.slow),
])
def test_a_work_limit_stops_at_the_same_point_however_the_clock_runs(monkeypatch, tmp_path, spec, horizon,
                                                                     work_limit):
    first = trustroute.synthesize(spec, horizon=horizon, work_limit=work_limit, time_limit=SLOW,
                                  out=tmp_path / "first.json")
    monkeypatch.setattr(time, "perf_counter", _dragging_clock())
    second = trustroute.synthesize(spec, horizon=horizon, work_limit=work_limit, time_limit=SLOW,
                                   out=tmp_path / "second.json")
    assert first.stopped_by == second.stopped_by == "work limit"
    assert first.upper - first.lower > 1e-3              # honestly unconverged
    assert (first.lower, first.upper) == (second.lower, second.upper)
    assert _untimed(first.stats.to_dict()) == _untimed(second.stats.to_dict())
    assert _policy_file(tmp_path / "first.json") == _policy_file(tmp_path / "second.json")


@pytest.fixture(scope="module")
def converged():
    """φ1 at H = 10 without a work limit, run to convergence once for the two tests that need it
    (a converged run stops where the search does, whatever the clock)."""
    return trustroute.synthesize("phi1", horizon=10, time_limit=SLOW)


def test_the_dragging_clock_stops_a_run_on_its_time_limit(monkeypatch, converged):
    """The control: without a work limit the same clock ends the search early."""
    assert converged.stopped_by == "convergence"
    monkeypatch.setattr(time, "perf_counter", _dragging_clock(0.05))
    assert trustroute.synthesize("phi1", horizon=10, time_limit=DRAGGED_LIMIT).stopped_by == "time limit"


def test_the_time_limit_still_stops_a_run_under_a_work_limit(monkeypatch):
    monkeypatch.setattr(time, "perf_counter", _dragging_clock(0.05))
    result = trustroute.synthesize("phi1", horizon=10, time_limit=DRAGGED_LIMIT, work_limit=10**12)
    assert result.stopped_by == "time limit" and result.upper - result.lower > 1e-3


def test_a_work_limit_that_is_not_reached_changes_nothing(converged):
    free = converged
    limited = trustroute.synthesize("phi1", horizon=10, time_limit=SLOW, work_limit=10**9)
    assert free.stopped_by == limited.stopped_by == "convergence"
    assert (free.lower, free.upper) == (limited.lower, limited.upper)


@pytest.mark.slow
def test_the_runs_of_a_population_synthesis_share_the_work_limit(monkeypatch):
    """The Bayes run, the candidate priors and the per-type evaluations between them are scheduled
    on the work done (policies/synthesis/budget.py's RunSchedule)."""
    settings = dict(horizon=6, population=POPULATION, objective="robust", grid_points=1, work_limit=30_000,
                    time_limit=SLOW)
    first = trustroute.synthesize("phi1_strict", **settings)
    monkeypatch.setattr(time, "perf_counter", _dragging_clock())
    second = trustroute.synthesize("phi1_strict", **settings)
    assert first.result.stopped_by == second.result.stopped_by == "work limit"
    assert (first.lower, first.upper, first.candidates) == (second.lower, second.upper, second.candidates)
    assert [(v.lower, v.upper) for v in first.type_values] == [(v.lower, v.upper) for v in second.type_values]


def test_a_robust_population_synthesis_under_a_work_limit_ignores_a_slow_clock(monkeypatch, tmp_path):
    """Whether a candidate prior runs and the limit it is given follow the Bayes run's fixed costs
    on the work clock (population.py, setup_seconds): a machine 20 times slower (or as loaded)
    runs the same candidates to the same robust policy, where fixed costs read off the wall clock
    would look 20 times larger and leave more candidates out."""
    settings = dict(horizon=6, population=POPULATION, objective="robust", work_limit=300_000,
                    time_limit=SLOW)
    first = trustroute.synthesize("phi1_strict", **settings, out=tmp_path / "first.json")
    monkeypatch.setattr(time, "perf_counter", _slow_clock(20.0))
    second = trustroute.synthesize("phi1_strict", **settings, out=tmp_path / "second.json")
    assert first.result.stopped_by == second.result.stopped_by == "work limit"
    assert first.candidates_skipped > 0          # the work limit, not the grid, ends the candidates
    assert (first.candidates, first.candidates_skipped) == (second.candidates, second.candidates_skipped)
    assert (first.lower, first.upper, first.prior) == (second.lower, second.upper, second.prior)
    assert [(v.lower, v.upper) for v in first.type_values] == [(v.lower, v.upper) for v in second.type_values]
    assert _policy_file(tmp_path / "first.json") == _policy_file(tmp_path / "second.json")


def test_a_robust_population_synthesis_the_wall_clock_cut_says_so(monkeypatch):
    """The control: the same slow clock past the time limit cuts the runs under a work limit never
    reached, and the result names the time limit (what result_digest refuses)."""
    monkeypatch.setattr(time, "perf_counter", _slow_clock(20.0))
    cut = trustroute.synthesize("phi1_strict", horizon=6, population=POPULATION, objective="robust",
                                work_limit=10**9, time_limit=5.0)
    assert cut.result.stopped_by == "time limit" and cut.candidates_skipped > 0


@pytest.mark.parametrize(("work_limit", "named"), [(None, "time limit"), (10**6, "work limit")])
def test_a_skipped_candidate_names_the_limit_that_leaves_it_no_room(work_limit, named):
    """The stderr line of a candidate prior the schedule cannot afford names the limit whose clock
    the schedule reads (work_clock.limit_reached)."""
    from trustroute.policies.synthesis.budget import RunSchedule, TimeBudget
    from trustroute.policies.work_clock import work_clock

    heard: list[str] = []
    with work_clock(work_limit, SLOW) as limit:
        schedule = RunSchedule(TimeBudget.start(limit), runs=2, on_phase=heard.append)
        schedule.skip("candidate prior [0.0, 1.0]")
    assert heard[0].endswith(f"candidate prior [0.0, 1.0]: skipped, too little of the {named} is left "
                             "for its run"), heard
    assert schedule.skipped == 1


@pytest.mark.parametrize(("skipped", "cut", "at_budget", "work_limit", "gap", "named"), [
    (0, 0, 0, None, 0.02, "candidate grid"),     # every candidate ran, none cut: the grid's own gap
    (0, 0, 0, None, 0.0, "convergence"),
    (0, 0, 1, None, 0.02, "node budget"),        # a run's search stopped at its node budget
    (1, 0, 0, None, 0.02, "time limit"),         # the clock skipped a candidate
    (0, 1, 1, None, 0.02, "time limit"),         # ... or cut a run short
    (0, 1, 0, 10**9, 0.02, "work limit"),        # the work limit did
])
def test_a_robust_synthesis_names_what_ended_it(skipped, cut, at_budget, work_limit, gap, named):
    """`population_stop`: a robust synthesis above tau names the limit only when its clock skipped a
    candidate prior or cut a run (RunSchedule.cut, population.run_end)."""
    from types import SimpleNamespace

    from trustroute.app.synthesis import population_stop
    from trustroute.policies.work_clock import installed, work_clock

    found = SimpleNamespace(objective="robust", candidates_skipped=skipped, runs_cut=cut, gap=gap,
                            runs_at_node_budget=at_budget,
                            result=SimpleNamespace(stats=None, lower=0.5, upper=0.5 + gap))
    with work_clock(work_limit, SLOW):
        assert population_stop(found, installed(), 1e-3) == named


def test_a_run_cut_by_its_limit_is_told_from_one_a_cap_or_convergence_ended(converged):
    from trustroute.policies.synthesis.population import run_end
    from trustroute.policies.work_clock import LIMITS

    assert run_end(converged) == "convergence"
    short = trustroute.synthesize("phi1", horizon=10, work_limit=2_000, time_limit=SLOW)
    assert short.stopped_by == "work limit" and run_end(short) in LIMITS
    capped = dataclasses.replace(short, stats=dataclasses.replace(short.stats, stopped="depth cap"))
    assert run_end(capped) == "depth cap"


def test_a_search_stopped_by_its_node_budget_says_so(capsys, tmp_path):
    """A search that stops at its node budget, long before its time limit, says so: `stopped_by` is
    "node budget" in the API and in --json (not "time limit": more time would not have moved its
    bounds), and the command's summary says so in a line."""
    from tests.cli import cli_json, run_cli
    from trustroute.policies.synthesis.result import SearchRun

    # the search alone: cluster policies after an unconverged search would take half its limit
    result = trustroute.synthesize("phi1", horizon=8, tau=1e-9, time_limit=60.0, clusters="off",
                                   node_budget=300)
    assert result.stopped_by == "node budget"
    assert result.upper - result.lower > 1e-9
    assert max(run.nodes for run in result.stats.runs if isinstance(run, SearchRun)) >= 300
    command = ["synth", "phi1", "--horizon", "8", "--tau", "1e-9", "--time-limit", "60", "--clusters", "off",
               "--node-budget", "300"]
    payload = cli_json(capsys, *command, "--out", str(tmp_path / "a.json"))
    assert payload["stopped_by"] == "node budget"
    code, out, err = run_cli(capsys, *command, "--out", str(tmp_path / "b.json"))
    assert code == 0, err
    assert "the search stopped at its node budget" in out and "would not tighten" in out


def test_a_larger_node_budget_lets_the_same_search_converge():
    """The control: with a node budget the search never reaches, the same call converges."""
    result = trustroute.synthesize("phi1", horizon=8, tau=1e-9, time_limit=60.0, clusters="off",
                                   node_budget=10**7)
    assert result.stopped_by == "convergence"


def test_a_population_search_stopped_by_its_node_budget_says_so():
    """The Bayes objective's bounds are its one search's: stopped at the node budget, it says so. The
    robust objective whose runs stopped at their node budget, none skipped or cut by the limit, says
    so too (not the time limit, which ended none of them)."""
    from trustroute.app.synthesis import stop_notes

    bayes = trustroute.synthesize("phi1", horizon=8, time_limit=10.0, population=POPULATION,
                                  objective="bayes", node_budget=300)
    assert bayes.result.stopped_by == "node budget"
    robust = trustroute.synthesize("phi1", horizon=8, time_limit=SLOW, population=POPULATION,
                                   objective="robust", node_budget=300, grid_points=1)
    assert (robust.candidates_skipped, robust.runs_cut) == (0, 0) and robust.runs_at_node_budget > 0
    assert robust.result.stopped_by == "node budget"
    assert "stopped at its node budget" in stop_notes(robust.result, 1e-3, False)[1]


def test_a_bad_node_budget_is_one_error_line_with_its_fix(capsys):
    from tests.cli import assert_one_line_error, run_cli
    from trustroute.core.errors import InputError

    code, _, err = run_cli(capsys, "synth", "phi1", "--node-budget", "0")
    assert_one_line_error(code, err, "--node-budget")
    with pytest.raises(InputError, match="expected an integer >= 1"):
        trustroute.synthesize("phi1", horizon=8, node_budget=0)


# Two junctions joined by one road without incidents: the belief never moves off the uniform prior,
# so P(trust >= 6) > 0.5 never holds and every policy is worth 0; the unbounded abstraction, which
# forgets the prior after a few `none` roads, keeps U at 1 whatever the time.
STILL_TOWN = {"junctions": {"A": [0, 0], "B": [500, 0]}, "roads": [["A", "B"]],
              "incidents": {"A-B": "none", "B-A": "none"}}
STILL_SPEC = ('name = "still"\nstart = "A-B"\nformula = "F (back & high)"\n[states]\nback = ["B-A"]\n'
              "[beliefs.high]\ncoeffs = [0, 0, 0, 0, 0, 1, 1]\noffset = 0.5\n")


def test_an_unbounded_synthesis_that_runs_its_whole_schedule_says_so_not_time_limit(capsys, tmp_path):
    """Every bounded horizon, the unbounded search and the cluster rounds end long before the
    limit with [0, 1]: `stopped_by` is "depth cap" (more time would not move the bounds), in the API,
    in --json and in a line of the summary; a population's Bayes objective says the same. The same
    problem cut by a short limit still says "time limit"."""
    from tests.cli import cli_json, run_cli

    (tmp_path / "still.json").write_text(json.dumps(STILL_TOWN))
    (tmp_path / "still.toml").write_text(STILL_SPEC)
    town, spec = tmp_path / "still.json", tmp_path / "still.toml"
    result = trustroute.synthesize(spec, town, time_limit=60.0)
    assert (result.lower, result.upper) == (0.0, 1.0) and result.seconds < 30
    assert result.stopped_by == "depth cap" and result.stats.stopped == "depth cap"
    command = ["synth", str(spec), "--town", str(town), "--time-limit", "60"]
    assert cli_json(capsys, *command, "--out", str(tmp_path / "a.json"))["stopped_by"] == "depth cap"
    code, out, err = run_cli(capsys, *command, "--out", str(tmp_path / "b.json"))
    assert code == 0, err
    assert "every step of the unbounded synthesis ran to its end" in out and "would not tighten" in out
    bayes = trustroute.synthesize(spec, town, time_limit=60.0, population=POPULATION, objective="bayes")
    assert bayes.result.stopped_by == "depth cap"
    cut = trustroute.synthesize(spec, town, time_limit=DRAGGED_LIMIT, work_limit=1000)
    assert cut.stopped_by in ("work limit", "time limit") and cut.stats.stopped is None
