"""The study runner: resume after SIGKILL, damaged parts, failures, and backends agree.

Every test uses the model engine (fast) and the trust-free condition (no synthesis), with a
[population] so participants differ. "Identical dataset" = episodes.parquet (without the
wall-clock column) and roads.parquet equal value for value, in the same row order.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from tests.cli import run_cli
from trustroute.core.dataset import part_path
from trustroute.core.errors import InputError
from trustroute.harness.study import runner as runner_module
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_and_consolidate, run_study

REPO = Path(__file__).resolve().parents[2]
PYTHON = sys.executable


def _config_file(tmp_path: Path, participants: int, name: str = "study.toml") -> Path:
    path = tmp_path / name
    path.write_text(f"""[study]
participants = {participants}
seed = 11
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["free"]

[population]
concentration = 40.0
takeover_spread = 0.4
""")
    return path


def _run(config, out: Path, workers: int = 1, scheduler: str | None = None, **kwargs):
    return run_and_consolidate(
        config, out, workers, scheduler, progress=False, echo=lambda *_: None, **kwargs
    )


def _dataset(study_dir: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    episodes = pd.read_parquet(study_dir / "episodes.parquet").drop(columns=["wall_seconds"])
    roads = pd.read_parquet(study_dir / "roads.parquet")
    return episodes, roads


def _assert_same(a: Path, b: Path) -> None:
    ea, ra = _dataset(a)
    eb, rb = _dataset(b)
    pd.testing.assert_frame_equal(ea, eb)
    pd.testing.assert_frame_equal(ra, rb)


def _assert_complete(study_dir: Path, config) -> None:
    episodes, roads = _dataset(study_dir)
    planned = [t.episode_id for t in plan_episodes(config)]
    assert list(episodes["episode_id"]) == planned  # no gaps, no duplicates
    assert roads.groupby("episode_id").size().loc[planned].tolist() == (episodes["junctions"] + 1).tolist()
    assert not roads.duplicated(["episode_id", "index"]).any()


@pytest.mark.slow
def test_sigkill_mid_run_then_rerun_equals_uninterrupted(tmp_path, capsys):
    """The study killed is the real command in its own process (its process group killed as a
    terminal's would be); the rerun is the same command in this process (tests/cli.py), which
    reads what the killed run left as a new process would, without a second interpreter's start."""
    config_path = _config_file(tmp_path, participants=200)
    config = load_study_config(config_path)
    killed = tmp_path / "killed"
    command = [
        PYTHON,
        "-m",
        "trustroute",
        "study",
        str(config_path),
        "--out",
        str(killed),
        "--workers",
        "2",
        "--no-report",
    ]
    process = subprocess.Popen(
        command, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    parts = killed / "parts"
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline and process.poll() is None:
            if parts.is_dir() and sum(1 for _ in parts.glob("*.zip")) >= 30:
                break
            time.sleep(0.005)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)  # the study's own process group only
        process.wait(timeout=30)
    assert process.returncode == -signal.SIGKILL, "the study finished before it could be killed"
    done_before = sum(1 for _ in parts.glob("*.zip"))
    assert 0 < done_before < 400
    assert not (killed / "episodes.parquet").exists()

    code, out, err = run_cli(capsys, *command[3:])
    assert code == 0, err
    assert f"{done_before} already done" in out
    reference = tmp_path / "reference"
    _run(config, reference, workers=2)
    _assert_complete(killed, config)
    _assert_same(killed, reference)


def test_damaged_parts_are_detected_and_rerun(tmp_path):
    config = load_study_config(_config_file(tmp_path, participants=6))
    study = tmp_path / "study"
    _run(config, study)
    reference = tmp_path / "reference"
    _run(config, reference)
    _assert_same(study, reference)
    tasks = plan_episodes(config)
    truncated = part_path(study, tasks[1].episode_id)
    truncated.write_bytes(truncated.read_bytes()[: truncated.stat().st_size // 2])
    flipped = part_path(study, tasks[4].episode_id)
    data = bytearray(flipped.read_bytes())
    middle = len(data) // 3
    data[middle : middle + 8] = bytes(b ^ 0xFF for b in data[middle : middle + 8])
    flipped.write_bytes(bytes(data))
    (study / "parts" / f".tmp-{tasks[2].episode_id}.zip.999").write_bytes(b"half a file")
    run, _ = _run(config, study)
    assert sorted(run.damaged) == sorted([tasks[1].episode_id, tasks[4].episode_id])
    assert run.skipped == len(tasks) - 2 and run.ran == 2
    assert not list((study / "parts").glob(".tmp-*"))
    _assert_complete(study, config)
    _assert_same(study, reference)
    # a finished study reruns nothing and stays identical
    again, _ = _run(config, study)
    assert again.ran == 0 and again.skipped == len(tasks)
    _assert_same(study, reference)


def test_failed_episode_is_recorded_retried_once_and_never_stops_the_study(tmp_path, monkeypatch):
    config = load_study_config(_config_file(tmp_path, participants=4))
    tasks = plan_episodes(config)
    always, flaky = tasks[2].episode_id, tasks[5].episode_id
    real = runner_module.engine_function(config.engine)
    attempts: dict[str, int] = {}

    def broken_engine(setup, policy, driver, episode_id, seed):
        attempts[episode_id] = attempts.get(episode_id, 0) + 1
        if episode_id == always or (episode_id == flaky and attempts[episode_id] == 1):
            raise RuntimeError(f"simulated crash in {episode_id}")
        return real(setup, policy, driver, episode_id, seed)

    monkeypatch.setattr(runner_module, "engine_function", lambda engine: broken_engine)
    study = tmp_path / "study"
    run, manifest = _run(config, study)
    assert run.failed == [always] and run.retried == 2
    assert attempts[always] == 2 and attempts[flaky] == 2
    record = json.loads((study / "failures" / f"{always}.json").read_text())
    assert record["attempts"] == 2 and "simulated crash" in record["error"]
    assert [f["episode_id"] for f in manifest["failed_episodes"]] == [always]
    episodes, _ = _dataset(study)
    assert always not in set(episodes["episode_id"]) and flaky in set(episodes["episode_id"])
    assert len(episodes) == len(tasks) - 1

    monkeypatch.undo()
    run, manifest = _run(config, study)
    assert run.ran == 1 and not run.failed and manifest["failed_episodes"] == []
    assert not (study / "failures" / f"{always}.json").exists()
    _assert_complete(study, config)


@pytest.mark.slow
def test_dask_and_local_pool_give_identical_datasets(tmp_path):
    config = load_study_config(_config_file(tmp_path, participants=10))
    pool, dask = tmp_path / "pool", tmp_path / "dask"
    _run(config, pool, workers=2)
    run = run_study(config, dask, workers=2, scheduler="local", progress=False, dask_processes=False)
    assert run.backend.startswith("dask") and not run.failed
    from trustroute.harness.study.expected import expected_values
    from trustroute.harness.study.manifest import consolidate

    consolidate(dask, run.context, plan_episodes(config), config.content_hash, expected_values(run.context))
    _assert_complete(pool, config)
    _assert_same(pool, dask)
    serial = tmp_path / "serial"
    _run(config, serial, workers=1)
    _assert_same(pool, serial)


def test_manifest_and_refusing_a_different_study(tmp_path):
    config = load_study_config(_config_file(tmp_path, participants=2))
    study = tmp_path / "study"
    _, manifest = _run(config, study)
    assert manifest["config_hash"] == config.content_hash
    assert manifest["finished_episodes"] == manifest["planned_episodes"] == 4
    assert set(manifest["seeds"]["episodes"]) == {t.episode_id for t in plan_episodes(config)}
    assert manifest["packages"]["numpy"] and manifest["git_revision"]
    assert manifest["expected"]["phi1"]["free"]["exact_lower"] > 0
    other = load_study_config(_config_file(tmp_path, participants=3, name="other.toml"))
    with pytest.raises(InputError, match="different config"):
        _run(other, study)


def test_study_horizon_selects_the_policy_synthesized_for_it(tmp_path):
    """`horizon = 6` synthesizes "aware" for 6 junctions, caches it under that horizon, and the
    expected values report that policy's own certified bounds (not the default H = 20 entry)."""
    from trustroute.harness.study.context import aware_policy_path, study_context
    from trustroute.harness.study.expected import expected_values

    path = tmp_path / "study.toml"
    path.write_text(f"""[study]
participants = 2
seed = 3
engine = "model"
specs = ["phi1"]
conditions = ["aware"]
horizon = 6
policy_cache = "{tmp_path / 'cache'}"
""")
    config = load_study_config(path)
    context = study_context(config)
    cached = aware_policy_path(context.town, context.nominal, context.specs["phi1"], config)
    assert cached.is_file() and "aware-phi1-" in cached.name
    document = json.loads(cached.read_text())
    assert document["horizon"] == 6
    entry = expected_values(context)["phi1"]["aware"]
    assert entry["synthesized_horizon"] == 6
    assert entry["synthesized_lower"] == pytest.approx(document["lower"])
    # Within 6 junctions phi1 is worth what its shortest completion is worth (0.87), far below H = 20's ~1.
    assert entry["synthesized_upper"] < 0.95


def test_parts_of_another_dataset_format_are_rerun_not_mixed(tmp_path, monkeypatch):
    from trustroute.harness.study import parts as part_files
    from trustroute.harness.study.plan import EpisodeTask

    config = load_study_config(_config_file(tmp_path, participants=2))
    study = tmp_path / "study"
    _run(config, study)
    reference = tmp_path / "reference"
    _run(config, reference)
    old = part_path(study, plan_episodes(config)[0].episode_id)
    part = part_files.read_part(old)
    # A whole part (checksums intact) as a writer of dataset format 1 left it.
    with monkeypatch.context() as patch:
        patch.setattr(part_files, "DATASET_FORMAT", "1")
        old.write_bytes(part_files.encode_part(EpisodeTask(**part.task), part.summary, part.tables))
    with pytest.raises(part_files.PartError, match="dataset format '1'"):
        part_files.read_part(old)
    run, _ = _run(config, study)
    assert run.damaged == [old.stem] and run.ran == 1
    assert (study / "damaged" / old.name).exists()  # kept aside, not deleted
    _assert_same(study, reference)
