"""Every refusal of `trustroute study` comes before anything is written: a command that exits 2
creates no study folder, and leaves a folder it refuses as it was (its study.json and study.lock
untouched)."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli

CONFIG = """[study]
participants = 1
seed = {seed}
engine = "model"
specs = ["phi1"]
conditions = ["free"]
"""


def _config(tmp_path: Path, seed: int, name: str = "study.toml", extra: str = "") -> Path:
    path = tmp_path / name
    path.write_text(CONFIG.format(seed=seed) + extra)
    return path


def _closed_port() -> int:
    """A local port nothing listens on (bound, then released)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file's content and modification time (a rewrite with the same bytes still shows)."""
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_an_unreachable_scheduler_is_refused_before_the_study_folder_exists(capsys, tmp_path):
    out = tmp_path / "study"
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 1)), "--out", str(out),
                           "--scheduler", f"tcp://127.0.0.1:{_closed_port()}", "--no-report")
    assert_one_line_error(code, err, "--scheduler", "cannot reach the Dask scheduler")
    assert not out.exists()


def test_a_folder_holding_another_study_is_left_as_it_was(capsys, tmp_path):
    out = tmp_path / "study"
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 1)), "--out", str(out), "--workers", "1",
                           "--no-report")
    assert code == 0, err
    before = _snapshot(out)
    assert "study.lock" in before and "study.json" in before
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 2, "other.toml")), "--out", str(out),
                           "--workers", "1", "--no-report")
    assert_one_line_error(code, err, "different config")
    assert _snapshot(out) == before


def test_unknown_recorded_episodes_are_refused_before_the_study_folder_exists(capsys, tmp_path):
    out = tmp_path / "study"
    config = _config(tmp_path, 1, extra='record = ["p00000-nosuch-free"]\n').read_text()
    config = config.replace('engine = "model"', 'engine = "sumo"')
    (tmp_path / "study.toml").write_text(config)
    code, _, err = run_cli(capsys, "study", str(tmp_path / "study.toml"), "--out", str(out), "--no-report")
    assert_one_line_error(code, err, "study.record", "is not an episode of this study")
    assert not out.exists()


def test_a_usage_error_names_its_fix(capsys):
    code, _, err = run_cli(capsys, "synth", "phi1", "--horizn", "3")
    assert_one_line_error(code, err, "trustroute synth", "No such option", "use --horizon")
    code, _, err = run_cli(capsys, "synth", "phi1", "--belief-rule", "nope")
    assert_one_line_error(code, err, "--belief-rule", "one of bayes, paper")
    assert "--help)" not in err


def test_a_file_where_the_study_writes_a_folder_is_named_before_any_episode_runs(capsys, tmp_path):
    out = tmp_path / "study"
    config = _config(tmp_path, 1)
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1", "--no-report")
    assert code == 0, err
    for part in (out / "parts").iterdir():
        part.unlink()
    (out / "parts").rmdir()
    (out / "parts").write_text("not a folder")
    before = _snapshot(out)
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1", "--no-report")
    assert_one_line_error(code, err, f"{out}: parts: not a folder", "move", "pass another --out")
    assert _snapshot(out) == before


@pytest.mark.parametrize("mark", ["damaged", "missing"])
def test_a_study_whose_mark_is_lost_is_refused_to_another_config_and_resumed_by_its_own(mark, capsys,
                                                                                        tmp_path):
    out = tmp_path / "study"
    config = _config(tmp_path, 1)
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1", "--no-report")
    assert code == 0, err
    if mark == "damaged":
        (out / "study.json").write_text('{"config_hash": 5')
    else:
        (out / "study.json").unlink()
    before = _snapshot(out)
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 2, "other.toml")), "--out", str(out),
                           "--workers", "1", "--no-report")
    assert_one_line_error(code, err, f"{out}: study.json: {'unreadable' if mark == 'damaged' else 'missing'}",
                          "manifest.json", "pass another --out, or restore study.json")
    assert _snapshot(out) == before
    (out / "parts" / sorted(p.name for p in (out / "parts").iterdir())[0]).unlink()
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1", "--no-report")
    assert code == 0, err   # its own config: the manifest names it, so the run resumes
    assert json.loads((out / "study.json").read_text())["config_hash"] == json.loads(
        (out / "manifest.json").read_text())["config_hash"]
    assert not (out / "damaged").exists()
