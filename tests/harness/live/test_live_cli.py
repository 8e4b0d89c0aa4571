"""`trustroute live` refuses bad input with one line and exit code 2, before it serves anything."""

from __future__ import annotations

import pytest

from tests.cli import run_cli

from .conftest import TINY


def write_config(tmp_path, engine: str = "live") -> str:
    path = tmp_path / "live.toml"
    path.write_text(TINY.format(participants=1, specs='["phi1"]').replace('"live"', f'"{engine}"'))
    return str(path)


def test_a_missing_consent_file_is_one_line_and_exit_2(tmp_path, capsys):
    code, out, err = run_cli(capsys, "live", write_config(tmp_path), "--out", str(tmp_path / "study"),
                             "--consent", str(tmp_path / "missing.txt"))
    assert code == 2 and err.count("\n") == 1 and "consent" in err and out == ""
    assert not (tmp_path / "study").exists()


def test_a_config_of_another_engine_is_one_line_and_exit_2(tmp_path, capsys):
    code, _, err = run_cli(capsys, "live", write_config(tmp_path, "sumo"), "--out", str(tmp_path / "study"))
    assert code == 2 and err.count("\n") == 1 and 'engine = "live"' in err


def test_a_bad_pace_or_port_is_a_usage_error(tmp_path, capsys):
    for option in (["--pace", "0"], ["--pace", "nan"], ["--port", "70000"], ["--resume-within", "-1"]):
        code, _, err = run_cli(capsys, "live", write_config(tmp_path), *option)
        assert code == 2 and err.startswith("error:"), option


def test_a_folder_of_other_files_is_refused_by_the_rule_of_trustroute_study(tmp_path):
    """The live study takes its directory as `trustroute study` does: a folder of other files is
    refused (one line naming it), before anything is written in it."""
    from trustroute.core.errors import InputError
    from trustroute.harness.live.server import LiveStudy, ServerOptions

    from .conftest import tiny_config

    out = tmp_path / "home"
    out.mkdir()
    (out / "notes.txt").write_text("the user's own notes")
    study = LiveStudy(tiny_config(tmp_path), out, ServerOptions(pace=1000.0))
    with pytest.raises(InputError, match=r"home: --out: the folder holds files that are not a study's "
                                         r"\(notes.txt\) \(fix: pass a new or empty folder to --out"):
        study.open().close()
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
