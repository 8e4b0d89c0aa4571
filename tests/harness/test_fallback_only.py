"""A synthesis that returns no decision row is only its fallback, and every command says so:
`synth` in one line on stderr and `"fallback_only": true` in --json, `evaluate` the same, a study
on stderr and in its manifest, and the analysis marks the condition in its tables and report.
(phi1 needs 6 junctions: at horizon 1 or 3 synthesis answers by graph distance, without rows.)"""

from __future__ import annotations

import json

import pytest

from tests.cli import run_cli
from tests.harness.helpers import run_study
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH


def test_synth_and_evaluate_say_a_policy_without_rows_is_its_fallback(tmp_path, capsys):
    out = tmp_path / "h1.json"
    code, stdout, err = run_cli(capsys, "synth", "phi1", "--horizon", "1", "--out", str(out), "--json")
    assert code == 0, err
    answer = json.loads(stdout)
    assert answer["stats"]["policy_rows"] == 0 and answer["fallback_only"] is True
    warnings = [line for line in err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "0 rows" in warnings[0] and "free completion" in warnings[0]
    code, stdout, err = run_cli(capsys, "evaluate", "phi1", str(out), "--json")
    assert code == 0, err
    assert json.loads(stdout)["fallback_only"] is True and "only its fallback" in err


def test_a_policy_with_rows_is_not_flagged(tmp_path, capsys):
    out = tmp_path / "h8.json"
    code, stdout, err = run_cli(capsys, "synth", "phi1", "--horizon", "8", "--out", str(out), "--json")
    assert code == 0, err
    answer = json.loads(stdout)
    assert answer["stats"]["policy_rows"] > 0 and answer["fallback_only"] is False
    assert "warning" not in err
    code, stdout, err = run_cli(capsys, "evaluate", "phi1", str(out), "--json")
    assert code == 0 and "fallback_only" not in json.loads(stdout) and "warning" not in err


def test_the_api_result_says_what_drives_when_it_is_only_its_fallback():
    """A script reads it from the result (`fallback_only`: the fallback in the commands' words),
    as the commands print it; a population synthesis's from its `result`."""
    import trustroute
    from trustroute.app.synthesis import fallback_only

    only = trustroute.synthesize("phi1", horizon=1)
    assert only.fallback_only == fallback_only(only.policy) is not None
    assert "free completion" in only.fallback_only
    assert trustroute.synthesize("phi1", horizon=8).fallback_only is None
    robust = trustroute.synthesize("phi1", horizon=1, population="driver_population_three_types",
                                   objective="robust")
    assert robust.result.fallback_only is not None


def test_the_api_evaluation_says_what_drives_when_the_policy_is_only_its_fallback(tmp_path, capsys):
    """`trustroute.evaluate(...).fallback_only` is the fallback `trustroute evaluate` warns of, for a
    policy file and a SynthesisResult alike; None for a policy with rows and for "free"."""
    import trustroute

    out = tmp_path / "h1.json"
    only = trustroute.synthesize("phi1", horizon=1, out=out)
    code, _, err = run_cli(capsys, "evaluate", "phi1", str(out), "--json")
    assert code == 0 and "only its fallback" in err
    for policy in (out, only):
        said = trustroute.evaluate("phi1", policy).fallback_only
        assert said == only.fallback_only is not None and f"only its fallback, {said};" in err
    assert trustroute.evaluate("phi1", trustroute.synthesize("phi1", horizon=8)).fallback_only is None
    assert trustroute.evaluate("phi1", "free").fallback_only is None


def test_a_serialised_api_evaluation_says_what_drives_when_the_policy_is_only_its_fallback(tmp_path,
                                                                                           capsys):
    """`trustroute.evaluate(...).to_dict()` keeps `fallback_only`, the text the CLI warns of, which
    the CLI's --json gives as `"fallback_only": true`; a policy with rows has no such key."""
    import trustroute

    out = tmp_path / "h1.json"
    only = trustroute.synthesize("phi1", horizon=1, out=out)
    serialised = json.loads(json.dumps(trustroute.evaluate("phi1", out).to_dict()))
    code, stdout, err = run_cli(capsys, "evaluate", "phi1", str(out), "--json")
    assert code == 0 and json.loads(stdout)["fallback_only"] is True
    assert serialised["fallback_only"] == only.fallback_only is not None
    assert f"only its fallback, {serialised['fallback_only']};" in err
    assert "fallback_only" not in trustroute.evaluate("phi1", "free").to_dict()


@pytest.mark.slow
def test_a_robust_synthesis_without_rows_says_so(tmp_path, capsys):
    code, stdout, err = run_cli(capsys, "synth", "phi1", "--horizon", "3", "--population",
                                str(EXAMPLE_POPULATION_PATH), "--objective", "robust",
                                "--out", str(tmp_path / "robust.json"), "--json")
    assert code == 0, err
    answer = json.loads(stdout)
    assert answer["fallback_only"] is True and answer["stats"]["policy_rows"] == 0
    assert "the robust policy for phi1 has no synthesized decision" in err
    code, stdout, err = run_cli(capsys, "evaluate", "phi1", str(tmp_path / "robust.json"), "--population",
                                str(EXAMPLE_POPULATION_PATH), "--json")
    assert code == 0 and json.loads(stdout)["fallback_only"] is True and "only its fallback" in err


@pytest.mark.slow
def test_a_study_marks_a_condition_whose_policy_is_its_fallback(tmp_path, capsys):
    from trustroute.analysis.study.analysis import study_analysis
    from trustroute.analysis.study.display import FALLBACK_MARK, display_tables, format_table
    from trustroute.analysis.study.report import write_report

    run_study(tmp_path / "study.toml", f"""[study]
participants = 2
seed = 5
engine = "model"
specs = ["phi1"]
conditions = ["aware", "free"]
horizon = 3
policy_cache = "{tmp_path / 'cache'}"
""", tmp_path / "out")
    assert "aware policy for phi1 has no synthesized decision" in capsys.readouterr().err
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert "free completion" in manifest["expected"]["phi1"]["aware"]["fallback_only"]
    assert "fallback_only" not in manifest["expected"]["phi1"]["free"]
    analysis = study_analysis(tmp_path / "out", resamples=20)
    shown = display_tables(analysis)["cells"]["condition"].tolist()
    assert shown == [f"aware{FALLBACK_MARK}", "free"]
    assert "Warning: the aware policy for phi1 has no synthesized decision" in format_table(analysis)
    write_report(tmp_path / "out", analysis)
    report = (tmp_path / "out" / "report.md").read_text()
    assert "**Warning: the aware policy for phi1" in report and f"aware{FALLBACK_MARK}" in report


def test_the_warning_says_why_the_fallback_was_returned():
    from trustroute.app.synthesis import fallback_warning

    timed_out = fallback_warning("p", "the free completion", converged=False)
    outranked = fallback_warning("p", "the free completion", converged=False, outranked=True)
    proved = fallback_warning("p", "the free completion", converged=True, outranked=True)
    assert "nothing was synthesized in time" in timed_out
    # either stop a synthesis obeys is named as the one to raise
    assert all("--time-limit" in line and "--work-limit" in line for line in (timed_out, outranked))
    # synthesized candidates were valued and the fallback served the worst type best
    assert "no synthesized candidate was worth more" in outranked and "in time" not in outranked
    assert "within tau of the optimum" in proved
    lines = (timed_out, outranked, proved)
    assert len(set(lines)) == 3 and all("\n" not in line for line in lines)


def test_a_search_stopped_before_any_row_reports_l_below_the_fallbacks_exact_value(tmp_path, capsys):
    """A work limit too small for the first row returns only the free completion: the warning calls
    L a lower bound of the fallback's value, and the exact evaluation of the policy file is at least
    L (here L is 0: the search stopped before valuing the root)."""
    out = tmp_path / "w.json"
    code, stdout, err = run_cli(capsys, "synth", "phi1", "--work-limit", "3000", "--out", str(out),
                                "--json")
    assert code == 0, err
    answer = json.loads(stdout)
    assert answer["fallback_only"] is True and answer["stats"]["policy_rows"] == 0
    assert "only a lower bound of the fallback's value" in err
    code, stdout, err = run_cli(capsys, "evaluate", "phi1", str(out), "--json")
    assert code == 0, err
    exact = json.loads(stdout)
    assert exact["fallback_only"] is True
    assert answer["lower"] <= exact["lower"] and exact["lower"] > 0.9
