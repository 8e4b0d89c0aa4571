"""Run the `trustroute` command in-process, as the tests of every package do, and check the one-line
errors it prints for bad input files."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from pathlib import Path

import click
import pytest

from trustroute.core.errors import InputError
from trustroute.harness.cli import cli, main


def run_cli(capsys: pytest.CaptureFixture, *args: str) -> tuple[int, str, str]:
    """`trustroute ARGS`: (exit code, stdout, stderr). The CLI always ends with SystemExit."""
    with pytest.raises(SystemExit) as exit_info:
        main(list(args))
    captured = capsys.readouterr()
    return exit_info.value.code, captured.out, captured.err


def every_command(group: click.Group = cli, path: str = "") -> list[tuple[str, click.Command]]:
    """Every command of the CLI, the subcommands of its groups included, as ("population sample",
    command), in the order `--help` lists them."""
    found: list[tuple[str, click.Command]] = []
    context = click.Context(group)
    for name in group.list_commands(context):
        command = group.get_command(context, name)
        assert command is not None
        if isinstance(command, click.Group):
            found += every_command(command, f"{path}{name} ")
        else:
            found.append((f"{path}{name}", command))
    return found


def cli_json(capsys: pytest.CaptureFixture, *args: str) -> dict:
    """The JSON a command prints with --json (it must succeed)."""
    code, out, err = run_cli(capsys, *args, "--json")
    assert code == 0, err
    return json.loads(out)


def cli_study(capsys: pytest.CaptureFixture, config: Path, text: str, out: Path):
    """`trustroute study CONFIG --out OUT` on one worker without a report, the config `text` written
    to `config` first (it must succeed): the study's episodes table."""
    import pandas as pd

    config.write_text(text)
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1", "--no-report")
    assert code == 0, err
    return pd.read_parquet(out / "episodes.parquet")


def assert_one_line_error(code: int, err: str, *fragments: str) -> None:
    """Exit code 2 and one `error: ... (fix: ...)` line on stderr holding every fragment."""
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert "(fix: " in lines[0]


def refused_file(load: Callable[[Path], object], data: dict, path: Path) -> InputError:
    """The InputError that `load` raises on `path` written with `data` as JSON."""
    path.write_text(json.dumps(data))
    with pytest.raises(InputError) as error:
        load(path)
    return error.value


def assert_file_refused(capsys: pytest.CaptureFixture, load: Callable[[Path], object], option: str,
                        data: dict, path: Path, place: str, problem: str) -> InputError:
    """`load` refuses the file of `data` at `place` with `problem`, and `trustroute model OPTION FILE`
    prints the same as one error line naming the file and exits 2 with nothing on stdout."""
    error = refused_file(load, data, path)
    assert error.place == place
    assert problem in error.problem
    code, out, err = run_cli(capsys, "model", option, str(path))
    assert_one_line_error(code, err, str(path), place, problem)
    assert out == ""
    return error


def mutation_cases(cases) -> list:
    """(mutate, place, problem) cases of a bad input file as pytest parameters, each named by its
    mutation."""
    return [pytest.param(*case, id=case[0].__name__) for case in cases]


def mutated(document: dict, mutate: Callable[[dict], None]) -> dict:
    """A deep copy of a good input `document`, changed by `mutate`."""
    out = copy.deepcopy(document)
    mutate(out)
    return out
