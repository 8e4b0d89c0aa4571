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


def unlisted(paths: dict[str, str], folder: Path) -> list[str]:
    """The files under `folder` that no entry of "paths" names, itself or as a folder holding it."""
    listed = [Path(path) for path in paths.values()]
    return sorted(str(file) for file in folder.rglob("*") if file.is_file()
                  and not any(file == path or file.is_relative_to(path) for path in listed))


@pytest.mark.slow
def test_run_lists_every_file_of_its_sumo_files_folder(capsys, tmp_path):
    payload = cli_json(capsys, "run", "phi1", "--sumo-files", str(tmp_path / "sumo"))
    assert unlisted(payload["paths"], tmp_path / "sumo") == []
    assert payload["paths"]["net"] == str(tmp_path / "sumo" / "net.net.xml")


@pytest.mark.slow
def test_study_lists_its_recordings_and_plots(capsys, tmp_path):
    config = tmp_path / "study.toml"
    config.write_text('[study]\nparticipants = 1\nseed = 1\nengine = "sumo"\nspecs = ["phi1"]\n'
                      'conditions = ["free"]\nrecord = ["p00000-phi1-free"]\n')
    out = tmp_path / "out"
    payload = cli_json(capsys, "study", str(config), "--out", str(out), "--workers", "1")
    assert payload["paths"]["recordings"] == str(out / "recordings")
    assert payload["paths"]["plots"] == str(out / "plots")
    assert unlisted(payload["paths"], out / "recordings") == unlisted(payload["paths"], out / "plots") == []
    assert (out / "recordings" / "p00000-phi1-free.rrd").is_file() and any((out / "plots").iterdir())
