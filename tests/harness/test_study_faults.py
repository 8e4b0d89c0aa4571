"""Faults during studies: damaged parts, damaged caches, dying workers, killed parents, two runs.

Each fault is applied to a finished (or running) study and the rerun is compared with an
undamaged run of the same config: episodes (without the wall-clock column), roads, kinematics and
incidents equal value for value. SUMO is used where the kinematics and incidents tables are the
point (2 episodes); the model engine everywhere else.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pandas as pd
import pytest

from tests.cli import run_cli
from trustroute.core.dataset import (
    DAMAGED_DIR,
    INCIDENTS_FILE,
    KINEMATICS_FILE,
    LOCK_FILE,
    STUDY_FILE,
    part_path,
)
from trustroute.harness.study import runner as runner_module
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.context import study_context
from trustroute.harness.study.manifest import DamagedParts, consolidate
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_and_consolidate

REPO = Path(__file__).resolve().parents[2]
PYTHON = sys.executable


def _config(tmp_path: Path, participants: int, engine: str = "model", name: str = "study.toml") -> Path:
    path = tmp_path / name
    path.write_text(f"""[study]
participants = {participants}
seed = 5
engine = "{engine}"
specs = ["phi1"]
conditions = ["free"]
""")
    return path


def _run(config, out: Path, workers: int = 1):
    return run_and_consolidate(config, out, workers, None, progress=False, echo=lambda *_: None)


def _tables(study_dir: Path) -> dict[str, pd.DataFrame]:
    out = {"episodes": pd.read_parquet(study_dir / "episodes.parquet").drop(columns=["wall_seconds"]),
           "roads": pd.read_parquet(study_dir / "roads.parquet")}
    for name, file_name in (("kinematics", KINEMATICS_FILE), ("incidents", INCIDENTS_FILE)):
        if (study_dir / file_name).exists():
            out[name] = pd.read_parquet(study_dir / file_name)
    return out


def _assert_same(a: Path, b: Path) -> None:
    ta, tb = _tables(a), _tables(b)
    assert set(ta) == set(tb)
    for name in ta:
        pd.testing.assert_frame_equal(ta[name], tb[name], obj=name)


def _flip_bit_in_entry(path: Path, entry: str) -> None:
    """Flip one bit in the middle of one table's bytes inside a part."""
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo(entry)
    data = bytearray(path.read_bytes())
    header = 30 + len(info.filename.encode()) + len(info.extra)  # zip local file header
    position = info.header_offset + header + info.compress_size // 2
    data[position] ^= 0x10
    path.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def sumo_reference(tmp_path_factory):
    root = tmp_path_factory.mktemp("sumo")
    config = load_study_config(_config(root, participants=2, engine="sumo"))
    reference = root / "reference"
    _run(config, reference)
    tables = _tables(reference)
    assert len(tables["kinematics"]) > 0 and len(tables["incidents"]) > 0  # the faults below mean something
    return config, reference


FAULTS = ("flip_kinematics", "flip_incidents", "flip_roads", "delete", "swap", "truncate")


@pytest.mark.slow
@pytest.mark.parametrize("fault", FAULTS)
def test_damaged_part_is_detected_and_rerun_restores_the_tables(fault, sumo_reference, tmp_path):
    config, reference = sumo_reference
    study = tmp_path / "study"
    _run(config, study)
    tasks = plan_episodes(config)
    first, second = (part_path(study, t.episode_id) for t in tasks[:2])
    if fault.startswith("flip_"):
        _flip_bit_in_entry(first, f"{fault.removeprefix('flip_')}.arrows")
    elif fault == "delete":
        first.unlink()
    elif fault == "swap":
        first.write_bytes(second.read_bytes())  # another episode's (valid) part under this name
    elif fault == "truncate":
        first.write_bytes(first.read_bytes()[: first.stat().st_size // 2])
    run, _ = _run(config, study)
    assert run.ran == 1 and not run.failed
    assert run.damaged == ([] if fault == "delete" else [tasks[0].episode_id])
    if fault != "delete":
        assert (study / DAMAGED_DIR / first.name).exists()  # moved aside, not lost
    _assert_same(study, reference)


def test_consolidation_verifies_every_part_again(tmp_path, monkeypatch):
    """A part damaged after the run's resume check is refused at consolidation (and moved aside),
    and run_and_consolidate re-runs it instead of publishing the damaged table."""
    config = load_study_config(_config(tmp_path, participants=3))
    study, reference = tmp_path / "study", tmp_path / "reference"
    _run(config, study)
    _run(config, reference)
    tasks = plan_episodes(config)
    victim = part_path(study, tasks[2].episode_id)
    _flip_bit_in_entry(victim, "roads.arrows")
    with pytest.raises(DamagedParts) as error:
        consolidate(study, study_context(config), tasks, config.content_hash)
    assert error.value.episode_ids == [tasks[2].episode_id] and not victim.exists()

    real_consolidate = runner_module._consolidate_run
    calls = []

    def damage_then_consolidate(context, run, echo, progress=False):
        if not calls:  # damage a part between the run and its consolidation, once
            _flip_bit_in_entry(part_path(study, tasks[1].episode_id), "roads.arrows")
        calls.append(run)
        return real_consolidate(context, run, echo, progress)

    monkeypatch.setattr(runner_module, "_consolidate_run", damage_then_consolidate)
    _run(config, study)
    assert len(calls) == 2 and calls[1].damaged == [] and calls[1].ran == 1
    _assert_same(study, reference)


# -- caches ------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("damage", ["zero_byte_json", "truncated_npz", "zero_byte_npz", "garbage_json"])
def test_damaged_cached_policy_is_rebuilt_with_a_notice(damage, town, driver, tmp_path):
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.resolve import aware_cache_path, aware_policy
    from trustroute.policies.routing.files import array_path, load_policy

    spec = load_spec(REPO / "trustroute" / "core" / "specs" / "phi1.toml", town)
    cache = tmp_path / "cache"
    notices: list[str] = []
    first = aware_policy(town, driver, spec, cache, horizon=6, notice=notices.append)
    entry = aware_cache_path(town, driver, spec, cache, horizon=6)
    assert entry.is_file() and not notices
    if damage == "zero_byte_json":
        entry.write_bytes(b"")
    elif damage == "garbage_json":
        entry.write_text('{"format": "trustroute-policy", "version": 1, ')
    elif damage == "truncated_npz":
        arrays = array_path(entry)
        arrays.write_bytes(arrays.read_bytes()[:-100])
    else:
        array_path(entry).write_bytes(b"")
    rebuilt = aware_policy(town, driver, spec, cache, horizon=6, notice=notices.append)
    assert len(notices) == 1 and "\n" not in notices[0] and entry.name in notices[0]
    assert load_policy(entry, town, driver, spec).table.rows == first.table.rows  # healed on disk
    assert rebuilt.table.rows == first.table.rows
    assert not [p for p in cache.iterdir() if p.name.startswith(".tmp-")]
    again = aware_policy(town, driver, spec, cache, horizon=6, notice=notices.append)
    assert again.table.rows == first.table.rows and len(notices) == 1  # no notice once healed


@pytest.mark.slow
def test_two_processes_filling_one_cache_entry_are_safe(tmp_path):
    cache = tmp_path / "cache"
    script = (
        "import sys\n"
        "from trustroute.networks.town import load_town\n"
        "from trustroute.participants.driver_model import load_driver_model\n"
        "from trustroute.policies.logic.spec import load_spec\n"
        "from trustroute.policies.resolve import aware_policy\n"
        "town = load_town(); driver = load_driver_model()\n"
        f"spec = load_spec({str(REPO / 'trustroute' / 'core' / 'specs' / 'phi1.toml')!r}, town)\n"
        f"policy = aware_policy(town, driver, spec, {str(cache)!r}, horizon=8)\n"
        "print(policy.table.rows)\n"
    )
    processes = [subprocess.Popen([PYTHON, "-c", script], cwd=REPO, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [p.communicate(timeout=300) for p in processes]
    assert [p.returncode for p in processes] == [0, 0], [r[1] for r in results]
    assert results[0][0] == results[1][0]  # both got the same policy
    assert not any("notice" in r[1] for r in results)  # neither saw a half-written entry
    names = sorted(p.name for p in cache.iterdir())
    assert [n for n in names if n.endswith(".json")] and not [n for n in names if n.startswith(".tmp-")]


# -- workers --------------------------------------------------------------------------------------------


def test_a_worker_killed_twice_fails_only_its_episode_and_a_rerun_completes(tmp_path, monkeypatch, capsys):
    """The worker running one episode is SIGKILLed on both attempts: only that episode fails (with
    both reasons recorded), the study exits 1 naming it and writes no report, and a rerun
    completes the study with tables equal to an undisturbed run."""
    config_path = _config(tmp_path, participants=6)
    config = load_study_config(config_path)
    tasks = plan_episodes(config)
    victim = tasks[3].episode_id
    parent = os.getpid()
    real_run_task = runner_module.run_task

    def run_task_killing_one_worker(context, study_dir, task):
        if task.episode_id == victim and os.getpid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)
        return real_run_task(context, study_dir, task)

    monkeypatch.setattr(runner_module, "run_task", run_task_killing_one_worker)
    study = tmp_path / "study"
    code, out, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "2")
    assert code == 1, err
    assert victim in err and "1 episode failed" in err
    assert not (study / "report.md").exists()  # no report from an incomplete study unless asked
    record = json.loads((study / "failures" / f"{victim}.json").read_text())
    assert record["attempts"] == 2 and len(record["errors"]) == 2
    assert all("killed by SIGKILL" in e for e in record["errors"])
    episodes = pd.read_parquet(study / "episodes.parquet")
    assert sorted(episodes["episode_id"]) == sorted(t.episode_id for t in tasks if t.episode_id != victim)

    code, _, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "2",
                           "--report-anyway", "--no-report")
    assert code == 1  # still killed: --report-anyway does not hide the failure
    monkeypatch.undo()
    code, out, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "2",
                             "--no-report")
    assert code == 0, err
    assert not (study / "failures" / f"{victim}.json").exists()
    reference = tmp_path / "reference"
    _run(config, reference)
    _assert_same(study, reference)


def _children(pid: int) -> set[int]:
    """Every descendant of `pid` (from /proc)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            parents[int(entry.name)] = int(fields[1])
    found, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _start_long_study(tmp_path: Path) -> tuple[subprocess.Popen, Path, Path]:
    config_path = _config(tmp_path, participants=20_000)
    study = tmp_path / "study"
    process = subprocess.Popen(
        [PYTHON, "-m", "trustroute", "study", str(config_path), "--out", str(study), "--workers", "2",
         "--no-report"],
        cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if (study / "parts").is_dir() and sum(1 for _ in (study / "parts").glob("*.zip")) >= 10:
            break
        time.sleep(0.02)
    assert process.poll() is None, process.stderr.read().decode()[-2000:]
    return process, config_path, study


@pytest.mark.slow
@pytest.mark.parametrize("kill", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_workers_die_with_their_parent_and_a_second_run_is_refused(kill, tmp_path, capsys):
    process, config_path, study = _start_long_study(tmp_path)
    workers = _children(process.pid)
    try:
        assert len(workers) >= 2
        # a second run on the same directory while the first holds it
        code, _, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "1",
                               "--no-report")
        assert code == 2 and len(err.strip().splitlines()) == 1
        assert f"pid {process.pid}" in err and "in use" in err
        lock = json.loads((study / LOCK_FILE).read_text())
        assert lock["pid"] == process.pid and lock["host"] and lock["started_utc"]
        os.kill(process.pid, kill)
        process.wait(timeout=30)
        if kill == signal.SIGTERM:   # as Ctrl-C: code 130, the interrupted line last, no blank one
            from trustroute.harness.cli import interrupted_line

            lines = process.stderr.read().decode().splitlines()
            assert process.returncode == 130 and lines[-1] == interrupted_line("study"), lines[-3:]
            assert len(lines) == 1 or lines[-2].strip(), lines[-3:]
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.05)
        survivors = [w for w in workers if _alive(w)]
        assert not survivors, f"workers {survivors} outlived their parent by 5 s"
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)
    assert (study / STUDY_FILE).exists()


# -- validation before writing ------------------------------------------------------------------------


def test_a_study_failing_validation_writes_nothing_and_runs_once_fixed(tmp_path, capsys):
    bad_spec = tmp_path / "mine.toml"
    phi1 = (REPO / "trustroute" / "core" / "specs" / "phi1.toml").read_text()
    bad_spec.write_text(phi1.replace("offset = 0.5", "offset = nan"))
    config_path = _config(tmp_path, 2)
    config_path.write_text(config_path.read_text().replace('specs = ["phi1"]', 'specs = ["mine.toml"]'))
    study = tmp_path / "out"
    code, _, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "1",
                           "--no-report")
    assert code == 2 and "mine.toml" in err
    assert not study.exists()  # not even the directory, let alone study.json
    bad_spec.write_text(phi1.replace('name = "phi1"', 'name = "mine"'))
    code, _, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "1",
                           "--no-report")
    assert code == 0, err
    assert (study / STUDY_FILE).exists() and (study / "manifest.json").exists()


# -- read-only and full disks -----------------------------------------------------------------------------


@pytest.fixture
def tiny_mount(tmp_path):
    """A real 256 KiB tmpfs (root only), for a full disk and a read-only file system."""
    point = tmp_path / "mount"
    point.mkdir()
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(point)],
                            capture_output=True, text=True)
    if result.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({result.stderr.strip()}); the in-process ENOSPC "
                    "test covers the write path")
    yield point
    subprocess.run(["umount", "-l", str(point)], check=False)


def _fill(point: Path) -> None:
    with (point / "filler").open("wb") as handle:
        try:
            while True:
                handle.write(b"\0" * 65536)
        except OSError:
            pass


def _no_temp_files(root: Path) -> bool:
    return not [p for p in root.rglob("*") if p.name.startswith(".tmp-")]


def test_full_disk_gives_one_line_and_no_partial_files(tiny_mount, tmp_path, capsys):
    _fill(tiny_mount)
    for args in (["synth", str(REPO / "trustroute/core/specs/phi1.toml"), "--horizon", "4", "--out",
                  str(tiny_mount / "p.json")],
                 ["spec", "check", str(REPO / "trustroute/core/specs/phi1.toml"), "--dot",
                  str(tiny_mount / "d.dot")]):
        code, _, err = run_cli(capsys, *args)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "no space left" in err, err
    assert sorted(p.name for p in tiny_mount.iterdir()) == ["filler"] and _no_temp_files(tiny_mount)
    # a study whose disk fills up: its episodes fail, the run exits non-zero, resumes once space is free
    config_path = _config(tmp_path, participants=2)
    code, _, err = run_cli(capsys, "study", str(config_path), "--out", str(tiny_mount / "study"),
                           "--workers", "1", "--no-report")
    assert code in (1, 2) and "Traceback" not in err and len(err.strip().splitlines()) <= 3, err
    assert _no_temp_files(tiny_mount)
    (tiny_mount / "filler").unlink()
    code, _, err = run_cli(capsys, "study", str(config_path), "--out", str(tiny_mount / "study"),
                           "--workers", "1", "--no-report")
    assert code == 0, err


def test_read_only_output_gives_one_line_and_writes_nothing(tiny_mount, tmp_path, capsys):
    subprocess.run(["mount", "-o", "remount,ro", str(tiny_mount)], check=True)
    spec = str(REPO / "trustroute/core/specs/phi1.toml")
    commands = [
        ["synth", spec, "--horizon", "4", "--out", str(tiny_mount / "p.json")],
        ["spec", "check", spec, "--dot", str(tiny_mount / "d.dot")],
        ["net", "build", "--out", str(tiny_mount / "nets")],
        ["evaluate", spec, "aware", "--cache-dir", str(tiny_mount / "cache")],
        ["run", "--spec", spec, "--out", str(tiny_mount / "run")],
        ["run", "--spec", spec, "--rrd", str(tiny_mount / "e.rrd")],
        ["study", str(_config(tmp_path, 2)), "--out", str(tiny_mount / "study"), "--no-report"],
    ]
    for args in commands:
        code, _, err = run_cli(capsys, *args)
        assert code == 2 and len(err.strip().splitlines()) == 1 and "read-only" in err, (args, err)
    assert list(tiny_mount.iterdir()) == []


@pytest.mark.parametrize("stop, raised", [
    (OSError(errno.ENOSPC, "No space left on device"), "no space left"),
    (KeyboardInterrupt(), None),   # Ctrl-C: the interrupt goes on, the half-written temporary file not
], ids=["enospc", "ctrl-c"])
def test_a_write_stopped_half_way_leaves_the_old_file_and_no_temp(tmp_path, monkeypatch, stop, raised):
    """The write path itself, without a mount: the disk fills up (or Ctrl-C) half-way through a write."""
    import trustroute.core.output_files as output_files
    from trustroute.core.errors import InputError

    target = tmp_path / "table.bin"
    target.write_bytes(b"old contents")
    real_open = open

    class FillsUp:
        def __init__(self, handle):
            self.handle = handle

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.handle.close()

        def write(self, data):
            self.handle.write(data[: len(data) // 2])
            raise stop

        def fileno(self):
            return self.handle.fileno()

        def flush(self):
            self.handle.flush()

    monkeypatch.setattr(output_files, "open", lambda path, mode: FillsUp(real_open(path, mode)),
                        raising=False)
    with pytest.raises(InputError if raised else KeyboardInterrupt, match=raised):
        output_files.atomic_write_bytes(target, b"new contents" * 1000, "dataset table")
    assert target.read_bytes() == b"old contents"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.bin"]


def test_an_episode_jammed_by_background_traffic_is_recorded_as_failed(tmp_path, monkeypatch, capsys):
    """Town01 with 200 background vehicles locks up in one of this study's episodes: that episode
    is recorded as failed with the jam's one line (not a traceback's last line) after its one run
    (not retried: the same seed jams again), the others run.
    The 7200 s sim-time cap is lowered to 300 s (the jam stands by then) to keep the test fast."""
    from trustroute.harness.simulation.sumo_start import SumoConfig

    config_path = tmp_path / "jam.toml"
    config_path.write_text('[study]\nparticipants = 2\nseed = 1\nengine = "sumo"\nspecs = ["phi1"]\n'
                           'conditions = ["free"]\nbackground_vehicles = 200\n')
    planned = runner_module.run_planned_episode
    monkeypatch.setattr(runner_module, "run_planned_episode", lambda context, task, rrd_path=None: planned(
        context, task, rrd_path, sumo_config=SumoConfig(max_sim_seconds=300.0)))
    study = tmp_path / "study"
    code, printed, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--no-report",
                                 "--json")
    assert code == 1 and "1 episode failed" in err, err
    (failure,) = sorted((study / "failures").glob("*.json"))
    record = json.loads(failure.read_text())
    assert record["attempts"] == 1 and len(record["errors"]) == 1   # the same seed jams again: run once
    assert json.loads(printed)["retried"] == 0
    assert all(error.startswith(f"TrafficJam: episode {record['episode_id']}: ") and "\n" not in error
               and "the 200 background vehicles jammed the town's roads (fix: run it with fewer" in error
               for error in record["errors"])
    planned_ids = [task.episode_id for task in plan_episodes(load_study_config(config_path))]
    episodes = pd.read_parquet(study / "episodes.parquet")
    assert list(episodes["episode_id"]) == [e for e in planned_ids if e != record["episode_id"]]


def test_an_episode_failing_on_bad_input_runs_once_and_a_crash_is_retried(tmp_path, monkeypatch, capsys):
    """An episode whose own input fails it (an InputError: here a TrafficJam, which the same seed
    meets again) is recorded as failed after one run, with its one-line reason; a crash gets its
    retry. The summary line, --json, the failure records, the manifest and the report count both."""
    from collections import Counter

    from trustroute.harness.simulation.background import STUCK_SECONDS, sim_time_cap_reached
    from trustroute.harness.simulation.sumo_start import SumoConfig

    config_path = _config(tmp_path, participants=4)
    tasks = plan_episodes(load_study_config(config_path))
    jammed, crashed = tasks[1].episode_id, tasks[2].episode_id
    jam = sim_time_cap_reached(jammed, "A-B", STUCK_SECONDS, SumoConfig(background_vehicles=200))
    runs: Counter[str] = Counter()
    planned = runner_module.run_planned_episode

    def run_planned_episode(context, task, rrd_path=None):
        runs[task.episode_id] += 1
        if task.episode_id == jammed:
            raise jam
        if task.episode_id == crashed:
            raise RuntimeError("a crash in the episode")
        return planned(context, task, rrd_path)

    monkeypatch.setattr(runner_module, "run_planned_episode", run_planned_episode)
    study = tmp_path / "study"
    code, printed, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "1",
                                 "--report-anyway")
    assert code == 1 and f"2 episodes failed (reasons in {study / 'failures'}" in err, err
    assert runs == {**{task.episode_id: 1 for task in tasks}, crashed: 2}
    assert "4 episodes planned: 0 already done, 4 run, 1 retried, 2 failed" in printed
    jam_line = f"TrafficJam: {jam}"
    records = {name: json.loads((study / "failures" / f"{name}.json").read_text())
               for name in (jammed, crashed)}
    assert (records[jammed]["attempts"], records[jammed]["errors"], records[jammed]["error"]) == (
        1, [jam_line], jam_line)
    assert "\n" not in jam_line and "jammed the town's roads (fix: run it with fewer" in jam_line
    assert records[crashed]["attempts"] == 2
    assert records[crashed]["errors"] == ["RuntimeError: a crash in the episode"] * 2
    manifest = json.loads((study / "manifest.json").read_text())
    assert manifest["run"]["retried"] == 1 and sorted(manifest["failed_episodes"], key=str) == sorted(
        [{"episode_id": jammed, "error": jam_line, "attempts": 1},
         {"episode_id": crashed, "error": "RuntimeError: a crash in the episode", "attempts": 2}], key=str)
    report = (study / "report.md").read_text()
    assert "## Failed episodes" in report and f"| {jammed} | 1 | {jam_line} |" in report

    runs.clear()   # a rerun runs the failed episodes again, by the same rule
    code, printed, err = run_cli(capsys, "study", str(config_path), "--out", str(study), "--workers", "1",
                                 "--no-report", "--json")
    assert code == 1
    assert runs == {jammed: 1, crashed: 2}
    payload = json.loads(printed)
    assert {key: payload[key] for key in ("planned", "skipped", "ran", "retried", "failed")} == {
        "planned": 4, "skipped": 2, "ran": 3, "retried": 1, "failed": sorted([jammed, crashed])}
