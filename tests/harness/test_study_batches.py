"""Model-engine studies in batches: one batch part per run of episodes gives the very dataset of
one part per episode, a damaged batch part re-runs its episodes, and a run killed between batches
resumes without duplicating rows. BATCH_MIN_EPISODES and BATCH_EPISODES are lowered so a small
study takes the batch path."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pandas as pd
import pytest

from trustroute.core.dataset import DAMAGED_DIR
from trustroute.harness.study import runner as runner_module
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.parts import PartError, batch_part_paths, read_batch_part
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_and_consolidate


def _config(tmp_path: Path):
    path = tmp_path / "study.toml"
    path.write_text("""[study]
participants = 5
seed = 11
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["free"]

[population]
concentration = 40.0
takeover_spread = 0.4
""")
    return load_study_config(path)


def _run(config, out: Path):
    return run_and_consolidate(config, out, 1, None, progress=False, echo=lambda *_: None)


def _tables(study: Path) -> list[pd.DataFrame]:
    return [pd.read_parquet(study / "episodes.parquet").drop(columns=["wall_seconds"]),
            pd.read_parquet(study / "roads.parquet")]


@pytest.fixture
def batched(monkeypatch):
    monkeypatch.setattr(runner_module, "BATCH_MIN_EPISODES", 1)
    monkeypatch.setattr(runner_module, "BATCH_EPISODES", 3)


@pytest.fixture
def reference(tmp_path_factory):
    """The study run with one part per episode (its size is below the batch threshold)."""
    root = tmp_path_factory.mktemp("reference")
    config = _config(root)
    _run(config, root / "study")
    assert not batch_part_paths(root / "study")
    return _tables(root / "study")


def _assert_same(study: Path, reference: list[pd.DataFrame]) -> None:
    for got, expected in zip(_tables(study), reference, strict=True):
        pd.testing.assert_frame_equal(got, expected)


def test_batches_give_the_dataset_of_one_part_per_episode(reference, batched, tmp_path):
    config = _config(tmp_path)
    run, _ = _run(config, tmp_path / "study")
    batches = batch_part_paths(tmp_path / "study")
    # 10 episodes: three batches of 3, and the last episode alone in its own part
    assert run.ran == 10 and len(batches) == 3
    tasks = plan_episodes(config)
    assert [p.episode_id for p in read_batch_part(batches[0])] == [t.episode_id for t in tasks[:3]]
    assert (tmp_path / "study" / "parts" / f"{tasks[9].episode_id}.zip").exists()
    _assert_same(tmp_path / "study", reference)


def test_a_damaged_batch_part_reruns_its_episodes(reference, batched, tmp_path):
    config = _config(tmp_path)
    study = tmp_path / "study"
    _run(config, study)
    victim = batch_part_paths(study)[1]  # episodes 3 to 5
    data = bytearray(victim.read_bytes())
    data[len(data) // 2] ^= 0xFF
    victim.write_bytes(bytes(data))
    with pytest.raises(PartError):
        read_batch_part(victim)
    run, _ = _run(config, study)
    tasks = plan_episodes(config)
    assert sorted(run.damaged) == sorted(t.episode_id for t in tasks[3:6]) and run.ran == 3
    assert (study / DAMAGED_DIR / victim.name).exists()
    _assert_same(study, reference)


def test_a_run_killed_between_batches_resumes_without_duplicates(reference, batched, tmp_path, monkeypatch):
    config = _config(tmp_path)
    study = tmp_path / "study"
    real = runner_module.run_batch
    calls = []

    def killed_after_two(context, study_dir, tasks):
        if len(calls) == 2:
            raise KeyboardInterrupt  # the run stops as a killed one does: two batch parts on disk
        calls.append(tasks)
        return real(context, study_dir, tasks)

    monkeypatch.setattr(runner_module, "run_batch", killed_after_two)
    with pytest.raises(KeyboardInterrupt):
        _run(config, study)
    assert len(batch_part_paths(study)) == 2
    monkeypatch.setattr(runner_module, "run_batch", real)
    run, _ = _run(config, study)
    assert run.skipped == 6 and run.ran == 4
    _assert_same(study, reference)


def test_a_batch_part_under_another_name_is_moved_aside(reference, batched, tmp_path):
    config = _config(tmp_path)
    study = tmp_path / "study"
    _run(config, study)
    first = batch_part_paths(study)[0]
    with zipfile.ZipFile(first) as archive:
        assert archive.namelist()[0] == "part.json"
    swapped = batch_part_paths(study)[2]
    first.write_bytes(swapped.read_bytes())  # another batch's (valid) part under this name
    with pytest.raises(PartError):
        read_batch_part(first)
    run, _ = _run(config, study)
    # the swapped file claims episodes that their own batch holds: none damaged, the first three rerun
    assert run.damaged == [] and run.ran == 3 and (study / DAMAGED_DIR / first.name).exists()
    _assert_same(study, reference)


def test_a_batch_keeps_an_episode_s_own_bad_input_when_its_part_cannot_be_written(tmp_path, monkeypatch):
    """An episode of a batch that failed on its own bad input stays that failure (not retried),
    while the episodes that finished fail by the batch part's write error (retried)."""
    from trustroute.core.errors import InputError
    from trustroute.harness.study.context import study_context

    config = _config(tmp_path)
    context = study_context(config)
    tasks = tuple(plan_episodes(config)[:3])
    planned = runner_module.run_planned_episode
    bad = InputError("episode", "road", "bad input", "fix it")

    def run_planned_episode(context, task, rrd_path=None):
        if task.episode_id == tasks[1].episode_id:
            raise bad
        return planned(context, task, rrd_path)

    def full_disk(*_args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runner_module, "run_planned_episode", run_planned_episode)
    monkeypatch.setattr(runner_module, "write_batch_part", full_disk)
    outcomes = runner_module.run_batch(context, str(tmp_path / "study"), tasks)
    assert [(o.episode_id, o.ok, o.retry) for o in outcomes] == [
        (tasks[0].episode_id, False, True), (tasks[1].episode_id, False, False),
        (tasks[2].episode_id, False, True)]
    assert outcomes[1].error == f"InputError: {bad}"
    assert outcomes[0].error == outcomes[2].error == "OSError: [Errno 28] No space left on device"


def test_an_episode_whose_own_part_cannot_be_written_is_retried(tmp_path, monkeypatch):
    """The write of an episode's part failing (an InputError too: a full disk's one line) is not the
    episode's own bad input: its outcome is retried, while the episode's own InputError is not."""
    from trustroute.core.errors import InputError
    from trustroute.core.output_files import write_error
    from trustroute.harness.study.context import study_context

    config = _config(tmp_path)
    context = study_context(config)
    task = plan_episodes(config)[0]
    full = write_error(tmp_path / "study" / "parts", "episode part", OSError(28, "No space left on device"))

    def full_disk(*_args):
        raise full

    monkeypatch.setattr(runner_module, "write_part_tables", full_disk)
    outcome = runner_module.run_task(context, str(tmp_path / "study"), task)
    assert (outcome.ok, outcome.retry, outcome.error) == (False, True, f"InputError: {full}")
    monkeypatch.undo()

    def bad_input(*_args, **_kwargs):
        raise InputError("episode", "road", "bad input", "fix it")

    monkeypatch.setattr(runner_module, "run_planned_episode", bad_input)
    outcome = runner_module.run_task(context, str(tmp_path / "study"), task)
    assert (outcome.ok, outcome.retry) == (False, False)
