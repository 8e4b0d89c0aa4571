"""Every refusal of `trustroute study` comes before anything is written: a command that exits 2
creates no study folder, and leaves a folder it refuses as it was (its study.json and study.lock
untouched)."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pandas as pd
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


# -- a folder that is not a study's --------------------------------------------------------------------

FOREIGN = {"notes.txt": "the user's own notes", "photos/holiday.jpg": "a photo",
           "study.json": "a file of the user's that happens to share the mark's name"}


@pytest.mark.parametrize("names", [("notes.txt", "photos/holiday.jpg"), ("study.json",)],
                         ids=["files", "a-file-named-like-the-mark"])
def test_a_folder_of_other_files_is_refused_and_left_as_it_was(names, capsys, tmp_path):
    out = tmp_path / "home"
    for name in names:
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(FOREIGN[name])
    before = _snapshot(out)
    shown = ", ".join(sorted(name.split("/")[0] for name in names))
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 1)), "--out", str(out), "--workers", "1",
                           "--no-report")
    assert_one_line_error(code, err, f"{out}: --out: the folder holds files that are not a study's ({shown})",
                          f"pass a new or empty folder to --out, e.g. {out / 'study'}")
    assert _snapshot(out) == before and sorted(p.name for p in out.iterdir()) == sorted(
        {name.split("/")[0] for name in names})


def test_the_api_refuses_a_folder_of_other_files_by_its_keyword(tmp_path):
    import trustroute
    from trustroute.core.errors import InputError

    out = tmp_path / "data"
    out.mkdir()
    (out / "results.csv").write_text("a,b\n1,2\n")
    config = {"study": {"participants": 1, "seed": 1, "engine": "model", "specs": ["phi1"],
                        "conditions": ["free"]}}
    with pytest.raises(InputError, match=r"data: out: the folder holds files that are not a study's "
                                         r"\(results.csv\) \(fix: pass a new or empty folder to out"):
        trustroute.run_study(config, out=out)
    assert [p.name for p in out.iterdir()] == ["results.csv"]


def test_an_empty_folder_is_a_new_study(capsys, tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 1)), "--out", str(out), "--workers", "1",
                           "--no-report")
    assert code == 0, err
    assert (out / "study.json").exists() and (out / "manifest.json").exists()


@pytest.mark.parametrize("made", [(".DS_Store",), ("Thumbs.db", "desktop.ini"), (".gitkeep",)])
def test_a_folder_holding_only_what_a_desktop_makes_in_it_is_empty(made, capsys, tmp_path):
    """A folder made in Finder or Explorer (which write their own files into a folder they show), or
    kept in git by a placeholder, is empty to the person who made it: the study is written into it,
    and those files are left as they were."""
    out = tmp_path / "made"
    out.mkdir()
    for name in made:
        (out / name).write_bytes(b"\x00\x01 the desktop's own")
    before = _snapshot(out)
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 1)), "--out", str(out), "--workers", "1",
                           "--no-report")
    assert code == 0, err
    assert (out / "study.json").exists() and (out / "manifest.json").exists()
    assert {name: entry for name, entry in _snapshot(out).items() if name in before} == before
    (out / "notes.txt").write_text("the user's own")   # beside them, a file of the person's is not
    other = tmp_path / "other"
    other.mkdir()
    for name in (*made, "notes.txt"):
        (other / name).write_bytes((out / name).read_bytes())
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 1)), "--out", str(other), "--workers", "1",
                           "--no-report")
    assert_one_line_error(code, err, f"{other}: --out: the folder holds files that are not a study's "
                          "(notes.txt)")


def test_the_mark_is_written_before_anything_else_in_the_folder(capsys, tmp_path, monkeypatch):
    """A run killed at any moment leaves its mark: when the lock is taken (the first thing written
    after the mark) the folder holds the mark and nothing else."""
    from trustroute.harness.study import runner

    out = tmp_path / "study"
    seen: list[list[str]] = []
    real_lock = runner.study_lock

    def lock_after_looking(study_dir):
        seen.append(sorted(p.name for p in Path(study_dir).iterdir()) if Path(study_dir).is_dir() else [])
        return real_lock(study_dir)

    monkeypatch.setattr(runner, "study_lock", lock_after_looking)
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 1)), "--out", str(out), "--workers", "1",
                           "--no-report")
    assert code == 0, err
    assert seen == [["study.json"]]


def test_a_folder_holding_only_the_mark_resumes_as_its_study(capsys, tmp_path):
    """A run killed right after marking its folder (the mark, perhaps the lock and a temporary file
    of a mark being written) is resumed by its config, and refused to another config."""
    config = _config(tmp_path, 1)
    reference = tmp_path / "reference"
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(reference), "--workers", "1",
                           "--no-report")
    assert code == 0, err
    out = tmp_path / "study"
    out.mkdir()
    (out / "study.json").write_bytes((reference / "study.json").read_bytes())
    (out / "study.lock").write_text("")
    (out / ".tmp-study.json.4242").write_text('{"config_hash": ')
    before = _snapshot(out)
    code, _, err = run_cli(capsys, "study", str(_config(tmp_path, 2, "other.toml")), "--out", str(out),
                           "--workers", "1", "--no-report")
    assert_one_line_error(code, err, f"{out}: study.json", "different config")
    assert _snapshot(out) == before
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1", "--no-report")
    assert code == 0, err
    episodes = [pd.read_parquet(folder / "episodes.parquet").drop(columns=["wall_seconds"])
                for folder in (out, reference)]
    pd.testing.assert_frame_equal(*episodes)


def test_a_study_killed_before_its_manifest_resumes_without_duplicating_rows(capsys, tmp_path, monkeypatch):
    """Killed after its episodes' parts were written and before consolidation wrote the manifest:
    the folder holds the mark and the parts (no manifest), and the rerun runs nothing again."""
    from trustroute.harness.study import runner

    config = _config(tmp_path, 1)
    config.write_text(config.read_text().replace("participants = 1", "participants = 3"))
    out = tmp_path / "study"

    def killed(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "consolidate", killed)
    code, _, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1", "--no-report")
    assert code == 130, err
    from trustroute.harness.cli import interrupted_line

    assert err == interrupted_line("study") + "\n" and "the same command resumes it" in err, err
    monkeypatch.undo()
    assert not (out / "manifest.json").exists() and (out / "study.json").exists()
    parts = sorted(p.name for p in (out / "parts").iterdir())
    assert len(parts) == 3   # every episode's part (3 participants, one spec, one condition)
    code, printed, err = run_cli(capsys, "study", str(config), "--out", str(out), "--workers", "1",
                                 "--no-report", "--json")
    assert code == 0, err
    assert {key: json.loads(printed)[key] for key in ("planned", "skipped", "ran", "failed")} == {
        "planned": 3, "skipped": 3, "ran": 0, "failed": []}
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert len(episodes) == len(set(episodes["episode_id"])) == len(parts)
    assert sorted(p.name for p in (out / "parts").iterdir()) == parts


def test_of_two_runs_marking_one_new_folder_at_once_the_second_config_is_refused(tmp_path, monkeypatch):
    """Both found the folder new; the other run's mark lands first: this run sees it, and refuses."""
    from trustroute.core.errors import InputError
    from trustroute.harness.study import resume
    from trustroute.harness.study.config import load_study_config

    mine = load_study_config(_config(tmp_path, 1))
    theirs = load_study_config(_config(tmp_path, 2, "other.toml"))
    out = tmp_path / "study"
    real_create = resume.atomic_create_bytes

    def another_run_marks_first(path, data, what, fix=""):
        real_create(path, json.dumps({"config_hash": theirs.content_hash}).encode(), what, fix)
        return real_create(path, data, what, fix)

    monkeypatch.setattr(resume, "atomic_create_bytes", another_run_marks_first)
    with pytest.raises(InputError, match="study.json: the directory holds a study with a different config"):
        resume.mark_study_dir(out, mine, mine.content_hash)
    assert json.loads((out / "study.json").read_text()) == {"config_hash": theirs.content_hash}
    assert [p.name for p in out.iterdir()] == ["study.json"]
