"""Hints name something that exists: every `trustroute COMMAND [SUBCOMMAND] [--option]` written in a
message of the package is a command of the click CLI (harness/cli.py), its subcommand, and its
option; the road hint names roads of the town; the Rerun hint serves on 127.0.0.1 only."""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import click
import pytest

from tests.test_architecture import parsed
from trustroute.core.errors import InputError
from trustroute.harness.cli import COMMANDS, cli

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("trustroute", "networks", "participants", "policies", "harness", "analysis")
HINT = re.compile(r"trustroute((?: [^\s`'\"(),;:]+)+)")
# Words that follow "trustroute" in prose about the package itself ("the trustroute that made it",
# "not a trustroute policy file", "the installed trustroute package"), never command names.
PROSE = frozenset({"that", "writes", "reads", "policy", "or", "episode", "package"})


def _docstrings(tree: ast.AST) -> set[int]:
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            first = node.body[0] if node.body else None
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                found.add(id(first.value))
    return found


@functools.cache
def message_hints() -> list[tuple[str, list[str]]]:
    """(where, tokens after "trustroute") for every mention in a string of the package's code
    (docstrings left out: they describe, they do not instruct). Read when a test asks, not when
    the tests are collected: each pytest process collects this file, one runs its tests."""
    hints = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = parsed(path)
            docstrings = _docstrings(tree)
            for node in ast.walk(tree):
                if (isinstance(node, ast.Constant) and isinstance(node.value, str)
                        and id(node) not in docstrings):
                    for match in HINT.finditer(node.value):
                        tokens = [token.rstrip(".") for token in match.group(1).split()]
                        hints.append((f"{path.relative_to(ROOT)}:{node.lineno}", tokens))
    return hints


def _options(command: click.Command) -> set[str]:
    return {"--help"} | {name for param in command.params for name in (*param.opts, *param.secondary_opts)}


def resolve(tokens: list[str]) -> str | None:
    """None when the tokens name an existing command (and subcommand and options), else the problem."""
    context = click.Context(cli)
    command = cli.get_command(context, tokens[0])
    if command is None:
        return f"no command {tokens[0]!r}"
    rest, path = tokens[1:], tokens[0]
    if isinstance(command, click.Group) and rest and not rest[0].startswith("-") and rest[0].islower():
        sub = command.get_command(context, rest[0])
        if sub is None:
            return f"no subcommand {rest[0]!r} of {tokens[0]!r}"
        command, rest, path = sub, rest[1:], f"{path} {rest[0]}"
    options = _options(command)
    unknown = [token for token in rest if token.startswith("--") and token.split("=")[0] not in options]
    return f"no option {unknown[0]} of {path}" if unknown else None


def test_the_scan_finds_the_hints():
    assert len(message_hints()) >= 20
    assert any(tokens[:2] == ["net", "build"] for _, tokens in message_hints())


def test_every_hinted_command_exists():
    problems = [f"{where}: 'trustroute {' '.join(tokens)}': {problem}" for where, tokens in message_hints()
                if tokens[0] not in PROSE and (problem := resolve(tokens)) is not None]
    assert problems == []


def test_prose_words_are_not_commands():
    assert not PROSE & set(COMMANDS)


def test_the_checker_catches_a_missing_command_subcommand_and_option():
    assert resolve(["model", "--town"]) is None and resolve(["net", "build", "--town", "FILE"]) is None
    assert resolve(["roads"]) == "no command 'roads'"
    assert resolve(["net", "list"]) == "no subcommand 'list' of 'net'"
    assert resolve(["synth", "--no-such-option"]) == "no option --no-such-option of synth"


def test_a_road_not_in_the_town_is_answered_with_roads_of_the_town(tmp_path):
    from trustroute.networks.town import load_town
    from trustroute.policies.logic.spec import load_spec

    town = load_town()
    spec = tmp_path / "spec.toml"
    spec.write_text('name = "s"\nstart = "E-A"\nformula = "F v"\n\n[states]\nv = ["E-Z"]\n')
    with pytest.raises(InputError) as error:
        load_spec(spec, town)
    assert "is not a directed road of the town" in error.value.problem
    named = set(re.findall(r"\b[A-Z]+-[A-Z]+\b", error.value.fix)) - {"U-V"}   # U-V: the form
    assert named and named <= set(town.states)
    assert "trustroute" not in error.value.fix


def test_the_rerun_hint_serves_on_127_0_0_1_only():
    from trustroute.harness.commands.replay import viewer_hint

    hint = viewer_hint(Path("study/recordings/e.rrd"))
    assert "--bind 127.0.0.1" in hint and "http://127.0.0.1:" in hint
    assert not re.search(r"rerun --web-viewer\b", hint)
    readme = (ROOT / "README.md").read_text()
    served = re.search(r"rerun (--serve-web --bind 127\.0\.0\.1 [^\n]*) F\.rrd", readme)
    assert served and f"rerun {served.group(1)} study/recordings/e.rrd" in hint


def test_the_rerun_viewer_is_named_on_path_or_by_its_absolute_path(tmp_path, monkeypatch):
    """A viewer beside the Python of a virtual environment that is not activated is named by its
    absolute path (a relative one breaks on the next `cd`); on PATH, or nowhere, plainly `rerun`."""
    import sys

    from trustroute.harness.commands.replay import rerun_command, viewer_hint

    bin_dir = tmp_path / "venv" / "bin"
    bin_dir.mkdir(parents=True)
    (bin_dir / "rerun").write_text("#!/bin/sh\n")
    (bin_dir / "rerun").chmod(0o755)
    monkeypatch.setattr(sys, "executable", str(bin_dir / "python"))
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.chdir(tmp_path / "venv")
    assert rerun_command() == str(bin_dir / "rerun")
    assert f"`{bin_dir / 'rerun'} e.rrd`" in viewer_hint(Path("e.rrd"))
    monkeypatch.setenv("PATH", str(bin_dir))
    assert rerun_command() == "rerun"
    (bin_dir / "rerun").unlink()
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert rerun_command() == "rerun"
