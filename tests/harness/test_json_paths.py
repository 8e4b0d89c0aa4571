"""`--json` has one shape for written files in every command: a "paths" object of name -> path,
present (empty) when the command wrote nothing."""

from __future__ import annotations

import pytest

from tests.cli import cli_json

COMMANDS = [
    ["evaluate", "phi1", "free"],
    ["baseline", "phi1"],
    ["spec", "check", "phi1"],
    ["model"],
    ["population", "show", "driver_population_real"],
    ["town", "roads", "pentagon"],
    ["synth", "phi1", "--horizon", "2", "--out", "{tmp}/p.json"],
    ["run", "phi1", "--out", "{tmp}/logs"],
]


@pytest.mark.parametrize("args", COMMANDS, ids=lambda args: " ".join(args[:2]))
def test_every_command_lists_its_written_files_under_paths(capsys, tmp_path, args):
    payload = cli_json(capsys, *(a.format(tmp=tmp_path) for a in args))
    paths = payload["paths"]
    assert isinstance(paths, dict) and all(isinstance(p, str) for p in paths.values())
    writes = any("{tmp}" in a for a in args)
    assert bool(paths) == writes
    assert all(str(tmp_path) in p for p in paths.values())
