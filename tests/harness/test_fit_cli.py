"""`trustroute fit`'s progress bars are drawn on a terminal only: on a stderr that is a file or a
pipe (a log, a CI job, `2> err.txt`) nothing but its lines, as every other command."""

from __future__ import annotations

from tests.cli import run_cli


def test_fit_draws_no_bar_on_a_stderr_that_is_not_a_terminal(model_study, capsys, tmp_path):
    code, out, err = run_cli(capsys, "fit", str(model_study), "--bootstrap", "2", "--out",
                             str(tmp_path / "driver.json"))
    assert code == 0, err
    assert "bootstrap" not in err and "\r" not in err, err
    assert "driver model written to" in out


def test_fit_says_where_its_bootstrap_intervals_are(model_study, capsys, tmp_path):
    """A researcher who asked for --bootstrap is told how many resamples ran and which file holds
    the intervals, as --check names its files."""
    import json

    out_path = tmp_path / "driver.json"
    code, out, err = run_cli(capsys, "fit", str(model_study), "--bootstrap", "2", "--out", str(out_path))
    assert code == 0, err
    written = tmp_path / "driver.bootstrap.json"
    resampled = json.loads(written.read_text())
    said = (f"bootstrap: 2 resamples of participants ({resampled['converged']} converged); 2.5-97.5 % "
            f"percentile intervals of every takeover probability and expected trust change in {written}")
    assert said in out, out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["driver.bootstrap.json", "driver.json"]


def test_options_of_the_types_fit_without_types_are_refused(model_study, capsys, tmp_path):
    """--max-types, --restarts and --shared-dynamics set the mixture fit: without --types they
    would change nothing, and the researcher who typed them would not know."""
    for extra in (["--max-types", "3"], ["--restarts", "2"], ["--shared-dynamics"]):
        code, out, err = run_cli(capsys, "fit", str(model_study), *extra, "--out", str(tmp_path / "d.json"))
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert f"{extra[0]} sets the fit of driver types, and --types is not given" in err, err
        assert not (tmp_path / "d.json").exists()


def test_the_help_of_types_gives_the_range_its_refusal_names(capsys):
    """`fit --help` shows --types' range, the one its refusal names (trustroute/core/ranges.py)."""
    from trustroute.core import ranges

    code, out, _ = run_cli(capsys, "fit", "--help")
    assert code == 0
    (line,) = [line for line in out.splitlines() if line.strip().startswith("--types ")]
    low, high = ranges.TYPES.kind.minimum, ranges.TYPES.kind.maximum
    assert line.split()[1:3] == ["INTEGER", f"{low}..{high}|auto"], line
    code, _, err = run_cli(capsys, "fit", "study", "--out", "model.json", "--types", str(high + 1))
    assert code == 2 and f"from {low} to {high}" in err and f"pass {low} to {high} driver types" in err, err


def test_fit_check_names_the_simulated_mean_trust_as_true_trust(model_study, capsys, tmp_path, monkeypatch):
    """The check's aware-vs-free rows average the simulated drivers' hidden trust, not reports: the
    terminal says "mean true trust", as the study tables name it beside the reported trust."""
    from trustroute.harness.commands import fit

    monkeypatch.setattr(fit, "CHECK_EPISODES", 200)
    code, out, err = run_cli(capsys, "fit", str(model_study), "--check", "--out",
                             str(tmp_path / "driver.json"))
    assert code == 0, err
    rows = [line for line in out.splitlines() if " drivers: satisfaction " in line]
    assert len(rows) == 8 and all(", mean true trust " in line for line in rows), out
