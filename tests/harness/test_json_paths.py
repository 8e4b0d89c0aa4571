"""`--json` has one shape for written files in every command: a "paths" object of name -> path,
present (empty) when the command wrote nothing."""

from __future__ import annotations

from pathlib import Path

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


def test_export_prints_one_json_object_with_its_package_and_key_under_paths(capsys, tmp_path, model_study):
    import shutil

    study_dir = tmp_path / "study"
    shutil.copytree(model_study, study_dir)
    payload = cli_json(capsys, "export", str(study_dir), "--out", str(tmp_path / "package"))
    assert payload["participants"] == 12
    assert payload["paths"] == {"package": str(tmp_path / "package"),
                                "export_key": str(study_dir / "export-key.json")}
    assert all(Path(path).exists() for path in payload["paths"].values())
