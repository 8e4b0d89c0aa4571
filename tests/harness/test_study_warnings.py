"""Every command that reads a finished study says what it cannot check of it, as the replay does
(tests/harness/test_replay.py): a manifest without `inputs.config_sha256` is one warning line on
stderr and listed under "warnings" in --json (harness/commands/output.py, `study_warnings`)."""

from __future__ import annotations

import json

import pytest

from tests.cli import run_cli
from tests.study_tables import study_copy

COMMANDS = {   # each command's arguments after the study directory (`{out}`: a new path)
    "analyze": [],
    "fit": ["--out", "{out}.json"],
    "fit --types": ["--types", "1", "--restarts", "1", "--out", "{out}.json"],
    "export": ["--out", "{out}"],
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_command_reading_a_study_warns_of_a_manifest_without_a_config_hash(command, pilot_study, tmp_path,
                                                                             capsys):
    study = study_copy(pilot_study(7), tmp_path / "study")

    def run(out: str) -> tuple[int, str, str]:
        extra = [arg.format(out=tmp_path / out) for arg in COMMANDS[command]]
        return run_cli(capsys, command.split()[0], str(study), *extra, "--json")

    code, out, err = run("recorded")
    assert code == 0 and json.loads(out)["warnings"] == [] and "warning" not in err, err
    manifest = json.loads((study / "manifest.json").read_text())
    del manifest["inputs"]["config_sha256"]   # as a manifest written before config hashes were recorded
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run("absent")
    warning = f"{study / 'manifest.json'}: inputs.config_sha256: absent"
    assert code == 0 and err.count("\n") == 1 and err.startswith(f"warning: {warning}"), err
    assert json.loads(out)["warnings"] == [err.removeprefix("warning: ").rstrip("\n")]
