"""One CLI convention: SPEC positional, --out FILE or DIRECTORY, --json with "paths", --quiet."""

from __future__ import annotations

import json
import re
from pathlib import Path

import click
import pytest

from tests.cli import every_command, run_cli

ROOT = Path(__file__).resolve().parents[2]

RESULT_COMMANDS = [("net", "build"), ("spec", "check"), ("model",), ("synth",), ("baseline",),
                   ("evaluate",), ("run",), ("study",), ("analyze",), ("fit",), ("demo",),
                   ("import", "carla-logs"), ("export",), ("withdraw",), ("replay",), ("plan",),
                   ("town", "import"), ("town", "roads"), ("population", "sample"), ("population", "show"),
                   ("peer", "storm"), ("peer", "paynt")]
OUT_IS = {("synth",): "FILE", ("fit",): "FILE", ("run",): "DIRECTORY", ("study",): "DIRECTORY",
          ("demo",): "DIRECTORY", ("net", "build"): "DIRECTORY", ("import", "carla-logs"): "DIRECTORY",
          ("export",): "DIRECTORY"}


@pytest.mark.parametrize("command", RESULT_COMMANDS, ids=" ".join)
def test_every_result_command_has_json_and_says_what_out_is(command, capsys):
    code, text, _ = run_cli(capsys, *command, "--help")
    assert code == 0
    assert "--json" in text and '"paths"' in text
    if command in OUT_IS:
        out_help = text[text.index("\n  --out "):].split("\n  -")[1]
        assert OUT_IS[command] in out_help, out_help


@pytest.mark.parametrize("command", [("synth",), ("baseline",), ("evaluate",), ("run",), ("spec", "check")],
                         ids=" ".join)
def test_spec_is_the_first_argument(command, capsys):
    code, text, _ = run_cli(capsys, *command, "--help")
    assert code == 0 and f"Usage: trustroute {' '.join(command)} [OPTIONS] SPEC" in text
    assert "--spec" not in text   # run's old --spec spelling is hidden


def _config(tmp_path) -> str:
    path = tmp_path / "tiny.toml"
    path.write_text('[study]\nparticipants = 2\nseed = 3\nengine = "model"\nspecs = ["phi1"]\n'
                    f'conditions = ["free"]\npolicy_cache = "{tmp_path / "cache"}"\n')
    return str(path)


@pytest.mark.slow
def test_study_json_quiet_and_analyze_writes_nothing_without_report(tmp_path, capsys):
    out = tmp_path / "study"
    code, text, err = run_cli(capsys, "study", _config(tmp_path), "--out", str(out), "--json", "--no-report")
    assert code == 0, err
    payload = json.loads(text)   # the whole of stdout is one JSON object
    assert payload["planned"] == 2 and payload["failed"] == []
    assert payload["paths"] == {"episodes": str(out / "episodes.parquet"),
                                "roads": str(out / "roads.parquet"), "manifest": str(out / "manifest.json")}
    assert all((out / name).is_file() for name in ("episodes.parquet", "roads.parquet", "manifest.json"))

    code, text, _ = run_cli(capsys, "study", _config(tmp_path), "--out", str(out), "--quiet", "--no-report")
    dataset_line = f"dataset: {out / 'episodes.parquet'}, {out / 'roads.parquet'}"
    assert code == 0 and text.splitlines() == [dataset_line]

    code, text, _ = run_cli(capsys, "analyze", str(out), "--json")
    assert code == 0 and json.loads(text)["paths"] == {}
    assert not (out / "report.md").exists() and not (out / "plots").exists()
    code, text, _ = run_cli(capsys, "analyze", str(out), "--json", "--report")
    paths = json.loads(text)["paths"]
    assert paths == {"report_markdown": str(out / "report.md"), "report_html": str(out / "report.html"),
                     "plots": str(out / "plots")}
    assert (out / "report.md").is_file() and (out / "report.html").is_file()
    assert any((out / "plots").iterdir())

    code, text, _ = run_cli(capsys, "study", _config(tmp_path), "--out", str(out), "--json")
    payload = json.loads(text)
    assert payload["skipped"] == 2 and payload["ran"] == 0
    assert payload["analysis"]["cells"][0]["n"] == 2
    assert set(payload["paths"]) == {"episodes", "roads", "manifest", "report_markdown", "report_html",
                                     "plots"}


def test_the_readme_names_exactly_the_commands_that_take_quiet():
    """README.md's list of the commands taking `--quiet` is the CLI's: a command given the option,
    or losing it, changes the sentence a user reads to silence it."""
    readme = " ".join((ROOT / "README.md").read_text().split())
    listed = re.search(r"((?:`[a-z -]+`(?:,| and)? )+)take `--quiet`", readme)
    assert listed, "README.md has no sentence naming the commands that take `--quiet`"
    named = set(re.findall(r"`([a-z -]+)`", listed.group(1)))
    quiet = {path for path, command in every_command()
             if any("--quiet" in param.opts for param in command.params)}
    assert named == quiet, f"README.md names {sorted(named)}; the commands taking --quiet: {sorted(quiet)}"


def test_every_spec_town_and_driver_says_it_takes_a_packaged_name():
    """SPEC, --town PATH and --driver PATH have one help text each (harness/commands/inputs.py)."""
    from trustroute.harness.commands.inputs import DRIVER_HELP, SPEC_HELP, TOWN_HELP

    seen = {"SPEC": 0, "--town": 0, "--driver": 0}
    for path, command in every_command():
        for param in command.params:
            if param.human_readable_name == "SPEC":
                seen["SPEC"] += 1
                assert SPEC_HELP in (command.help or ""), path
            elif "--town" in param.opts and param.type.name == "path":
                seen["--town"] += 1
                assert param.help.startswith(f"{TOWN_HELP} (default: "), (path, param.help)
            elif "--driver" in param.opts and path in ("synth", "baseline", "evaluate", "run", "model",
                                                       "peer storm", "peer paynt"):
                seen["--driver"] += 1
                assert param.help == DRIVER_HELP, (path, param.help)
    assert seen == {"SPEC": 7, "--town": 9, "--driver": 7}


def test_every_option_of_every_command_has_a_help_text():
    """`--help` explains every option of every command and subcommand (click shows an option
    without help as its flag and metavar alone)."""
    missing = [f"{path} {'/'.join(param.opts)}" for path, command in every_command()
               for param in command.params
               if isinstance(param, click.Option) and not (param.help or "").strip()]
    commands = {path for path, _ in every_command()}
    assert {"plan", "demo", "population sample", "peer storm", "import carla-logs"} <= commands
    assert missing == []
    assert [path for path, command in every_command() if not (command.help or "").strip()] == []


def test_the_study_and_the_demo_say_their_failed_episodes_in_one_wording(tmp_path):
    """One failed episode in the singular; the demo's line is the study's, with its own rerun."""
    from trustroute.core.dataset import FAILURES_DIR
    from trustroute.harness.commands.study import failed_line
    from trustroute.harness.study.runner import StudyRun

    def run(failed: list[str]) -> StudyRun:
        return StudyRun(tmp_path, planned=12, skipped=0, damaged=[], ran=12, failed=failed, retried=0,
                        seconds=1.0, backend="local")

    assert failed_line(run(["p0-phi1-free"]), "a rerun retries them") == (
        f"error: 1 episode failed (reasons in {tmp_path / FAILURES_DIR}; a rerun retries them): p0-phi1-free")
    eleven = [f"e{i}" for i in range(11)]
    demo = failed_line(run(eleven), "rerun the demo to retry them")
    assert demo.startswith(f"error: 11 episodes failed (reasons in {tmp_path / FAILURES_DIR}; rerun the "
                           "demo to retry them): e0, "), demo
    assert failed_line(run(eleven), "").endswith(", e9 ...")
