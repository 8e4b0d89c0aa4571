"""What `synth`'s text says of a run: why it stopped (the word `--json` gives as "stopped_by"),
how many candidate priors of the robust objective were not run and why, which per-type values are
exact and which only certified, and the type prior a policy table was built for told apart from
the weights the AV filters with."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np

from tests.cli import run_cli
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH
from trustroute.policies.synthesis.population import MAX_GRID_CANDIDATES, TypeValue
from trustroute.policies.synthesis.rounding import ModelRounding

ROBUST = ("--population", str(EXAMPLE_POPULATION_PATH), "--objective", "robust")


def _text_and_json(capsys, tmp_path, *args: str) -> tuple[str, dict]:
    code, text, err = run_cli(capsys, "synth", *args, "--quiet", "--out", str(tmp_path / "t.json"))
    assert code == 0, err
    code, out, err = run_cli(capsys, "synth", *args, "--json", "--out", str(tmp_path / "j.json"))
    assert code == 0, err
    return text, json.loads(out)


def test_the_text_says_why_the_search_stopped_in_the_word_json_gives(capsys, tmp_path):
    text, answer = _text_and_json(capsys, tmp_path, "phi1", "--work-limit", "2000")
    assert answer["stopped_by"] == "work limit", answer
    assert "stopped by: work limit, before the gap reached tau = 0.001\n" in text, text
    text, answer = _text_and_json(capsys, tmp_path, "phi1", "--horizon", "6")
    assert answer["stopped_by"] == "convergence", answer
    assert "stopped by: convergence (the gap reached tau = 0.001)\n" in text, text


def test_a_robust_run_of_the_whole_grid_names_the_grid_not_the_time_limit(capsys, tmp_path):
    """Every candidate prior runs, no run is cut, and the gap stays above tau: the gap is the grid
    search's own (it compares the grid's priors, not all policies), and no limit ended the call."""
    text, answer = _text_and_json(capsys, tmp_path, "phi1_strict", "--horizon", "6", *ROBUST,
                                  "--time-limit", "600")
    population = answer["population"]
    assert answer["gap"] > answer["tau"], answer
    assert answer["stopped_by"] == "candidate grid", answer
    assert "stopped by: candidate grid, before the gap reached tau = 0.001\n" in text, text
    assert population["candidates_skipped"] == population["runs_cut"] == 0, population
    assert population["candidates_not_needed"] == 0, population
    assert "every candidate prior of the grid ran and no run was cut by its limit" in text, text
    assert "time limit" not in text, text


def test_a_converged_run_the_wall_clock_passed_says_the_gap_reached_tau(monkeypatch):
    """Under a work limit a run the wall clock passed names the time limit (its result may depend on
    the load), but a gap that reached tau is not said to have stopped short of it."""
    import time

    import trustroute
    from trustroute.app.synthesis import reached_tau, stop_notes

    real, readings = time.perf_counter, [0]

    def dragging() -> float:      # each reading 0.05 s after the last: the wall limit passes early
        readings[0] += 1
        return real() + 0.05 * readings[0]

    monkeypatch.setattr(time, "perf_counter", dragging)
    found = trustroute.synthesize("phi2", horizon=6, population=EXAMPLE_POPULATION_PATH, objective="robust",
                                  time_limit=1.0, work_limit=10**9)
    monkeypatch.undo()
    assert found.result.stopped_by == "time limit" and found.gap <= 1e-3, (found.result.stopped_by, found.gap)
    assert reached_tau(found, 1e-3)
    assert stop_notes(found.result, 1e-3, reached_tau(found, 1e-3))[0] == (
        "stopped by: time limit, though the gap reached tau = 0.001: the wall clock passed the time limit "
        "under the work limit, so the result may depend on the machine's load")


def test_the_robust_summary_counts_the_candidate_priors_skipped_at_the_limit(capsys, tmp_path):
    """A work limit the Bayes run takes whole: grid priors are skipped; the text and the JSON count
    them, and with those run and those not needed they make up the grid (its 16 points but the
    population's weights, the Bayes run's)."""
    text, answer = _text_and_json(capsys, tmp_path, "phi1", *ROBUST, "--work-limit", "100000")
    population = answer["population"]
    skipped = population["candidates_skipped"]
    assert skipped > 0 and answer["stopped_by"] == "work limit", answer
    grid_run = [c for c in population["candidates"] if c["prior"] not in (None, population["weights"])]
    assert len(grid_run) + skipped + population["candidates_not_needed"] == MAX_GRID_CANDIDATES - 1
    assert f"; {skipped} more skipped, the limit leaving no time for their runs)" in text, text
    assert "stopped by: work limit, before the gap reached tau" in text, text


def test_a_per_type_value_is_exact_only_where_no_history_was_cut(capsys, tmp_path):
    from trustroute.harness.commands.synth import type_value_text

    rounding = ModelRounding(n=7, likelihood=4, matrix=4, rows=0, prior=2)
    exact = TypeValue.certified("a", 0.5, (0.25, 0.25), rounding, 20)
    cut = TypeValue.certified("b", 0.5, (0.25, 0.274), rounding, 20)
    assert exact.exact and not cut.exact
    assert exact.upper - exact.lower < 1e-12 and exact.lower < 0.25 < exact.upper
    assert type_value_text(exact) == "a (weight 0.5) exact [0.249999, 0.250001]"
    assert type_value_text(cut) == "b (weight 0.5) certified [0.249999, 0.274001]"
    # a synthesis whose evaluations are cut (unbounded, the limit reached): certified, never exact
    code, text, err = run_cli(capsys, "synth", "phi1", *ROBUST, "--work-limit", "100000", "--quiet",
                              "--out", str(tmp_path / "r.json"))
    assert code == 0, err
    per_type = next(line for line in text.splitlines() if line.startswith("returned policy per type"))
    assert "exact" not in per_type and per_type.count(" certified [") == 3, per_type
    # `evaluate --population` words its per-type values alike: the free route, evaluated in full
    code, text, err = run_cli(capsys, "evaluate", "phi1", "free", *ROBUST[:2])
    assert code == 0, err
    per_type = next(line for line in text.splitlines() if line.startswith("per type: "))
    assert per_type.count(" exact [") == 3 and "certified" not in per_type, per_type


def test_the_policy_tables_prior_is_not_the_avs_belief():
    """A candidate prior's policy: the text says its table was built for that prior and that the
    AV filters with the population's weights, never that the AV's prior is the candidate's."""
    from trustroute.harness.commands.synth import population_lines

    kinds = [SimpleNamespace(name=n, weight=w, lower=0.5, upper=0.5, exact=True)
             for n, w in (("builder", 0.4), ("flat", 0.3), ("wary", 0.3))]
    found = SimpleNamespace(lower=0.5, upper=0.6, gap=0.1, seconds=1.0, type_values=kinds,
                            mixture_value=(0.5, 0.5), worst_type_value=0.5, prior=(0.0, 0.75, 0.25),
                            population=SimpleNamespace(weights=np.array([0.4, 0.3, 0.3])),
                            bayes_lower=0.4, bayes_upper=0.6, candidates=[{}] * 3,
                            candidates_not_needed=0, candidates_skipped=0)
    text = "\n".join(population_lines("phi", 3, "robust", found, worst_bayes=0.3))
    assert "AV type prior" not in text
    assert ("policy table built for the type prior 0, 0.75, 0.25; the AV filters with the population's "
            "weights 0.4, 0.3, 0.3, its belief reweighted to that prior for the table") in text, text
    found.prior = (0.4, 0.3, 0.3)
    text = "\n".join(population_lines("phi", 3, "robust", found, worst_bayes=0.3))
    assert "policy table built for the population's weights 0.4, 0.3, 0.3, with which the AV filters" in text


def test_a_run_the_wall_clock_cut_after_its_gap_reached_tau_does_not_say_before_it():
    """`stopped_by` names the time limit whenever a run under a work limit reached the wall clock,
    converged or not (policies/work_clock.py): the text then says the gap reached tau, not that the
    limit came first."""
    from trustroute.app.synthesis import stop_line

    before = stop_line("time limit", 1e-3, False)
    assert before == "stopped by: time limit, before the gap reached tau = 0.001"
    cut_late = stop_line("time limit", 1e-3, True)
    assert "before the gap reached tau" not in cut_late, cut_late
    assert cut_late.startswith("stopped by: time limit, though the gap reached tau = 0.001")
    assert "load" in cut_late
    assert stop_line("convergence", 1e-3, True) == "stopped by: convergence (the gap reached tau = 0.001)"
