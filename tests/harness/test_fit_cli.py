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
