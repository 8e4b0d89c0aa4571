"""Run the whole suite the way `make test` does: `python -m tests.suite [PYTEST_ARGS...]`.

Two lanes run at once. The tests whose outcome depends on the wall clock (marked `wallclock`: a
live station paced in real time, a browser driven as a person would, a peer's wall-clock time
limit) mostly wait, and fail if starved of a core, so they run at normal priority: first the
`serial` browser session alone in its lane, then the other `wallclock` tests on one pytest-xdist
worker per core. The CPU-bound rest runs meanwhile at a lower priority (`nice`), on one worker per
core with work stealing, and takes every cycle the waiting lane leaves. Both lanes share one cache
root for nets and policies (tests/conftest.py, `temporary_cache`), so a policy one lane builds the
other reads. The exit code is the first lane's that failed; a lane that collects nothing is not a
failure (pytest's exit code 5).

The wall-clock lane collects only the test files that use its marks (`marked_files`): collecting
the whole suite costs each pytest process about 12 CPU-seconds. So that no test falls between the
lanes, each pytest process writes the tests it kept and the ones its `-m` left out to a ledger
(tests/conftest.py, `LEDGER_ENV`), and the suite fails unless the wall-clock lane ran exactly the
tests the CPU-bound lane left out. Given pytest arguments (paths, `-k`), both lanes take those
instead, and the ledger is not checked.

The wall-clock lane starts once the CPU-bound lane's workers have collected (their ledgers are
written), at most COLLECTION_WAIT seconds later: on a fresh clone the first processes compile
every module the suite imports, the project's and the installed packages', and each process that
starts before those caches exist compiles them all again (about 7 CPU-seconds each). The
wall-clock lane mostly waits and ends well before the CPU-bound one, so its start can wait.

Every Python process of the suite may write bytecode caches (`__pycache__`, ignored by git) even
where the environment says not to (PYTHONDONTWRITEBYTECODE): the suite starts dozens of processes
(pytest workers, live stations, study workers) that import the same modules, and without caches
each compiles them afresh and pytest rewrites every test module's assertions again, about 5
CPU-seconds per pytest process."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
NO_TESTS = 5      # pytest: nothing collected
NICENESS = 10     # the CPU-bound lane's: a paced test that wants its core gets about 90 % of it
CACHE_ENV = "TRUSTROUTE_TEST_CACHE"   # the cache root of every run (tests/conftest.py reads it)
LEDGER_ENV = "TRUSTROUTE_TEST_LEDGER"  # where each run writes the tests it kept and left out
WAITING_MARKS = ("wallclock", "serial")
COLLECTION_WAIT = 60.0   # s: the longest the wall-clock lane waits for the CPU-bound lane's collection


def applies(text: str, marks: tuple[str, ...] = WAITING_MARKS) -> bool:
    """Whether a test file's source applies any of `marks` (as `pytest.mark.NAME`)."""
    return re.search(rf"\bpytest\.mark\.({'|'.join(marks)})\b", text) is not None


def marked_files(marks: tuple[str, ...] = WAITING_MARKS) -> list[str]:
    """The test files that apply any of `marks`, relative to the repository."""
    return [str(path.relative_to(REPO)) for path in sorted((REPO / "tests").rglob("test_*.py"))
            if applies(path.read_text(), marks)]


def ledger(lane: Path, kind: str) -> set[str]:
    """The node ids every run of the lane whose folder is `lane` wrote as `kind` ("kept" or
    "left-out")."""
    ids: set[str] = set()
    for path in lane.glob(f"ledger/run*/*.{kind}"):
        ids.update(line for line in path.read_text().splitlines() if line)
    return ids


def lanes_disagree(root: Path) -> str:
    """'' when the wall-clock lane ran exactly the tests the CPU-bound lane left out; else what differs."""
    waiting, left_out = ledger(root / "wallclock", "kept"), ledger(root / "computing", "left-out")
    if waiting == left_out:
        return ""
    missing = sorted(left_out - waiting)
    twice = sorted(waiting - left_out)
    return (f"{len(missing)} test(s) left out by the CPU-bound lane did not run in the wall-clock lane "
            f"{missing[:5]}; {len(twice)} ran in both {twice[:5]} (fix: mark them with "
            f"pytest.mark.wallclock in the file itself, which marked_files reads)")


@dataclass(frozen=True)
class Run:
    """One pytest invocation of a lane: its marker expression, its worker count (0: in process) and
    the files it collects (none: what pytest's arguments or configuration say)."""
    marks: str
    workers: int
    files: list[str] = field(default_factory=list)


def pytest_command(run: Run, basetemp: Path, extra: list[str]) -> list[str]:
    command = [sys.executable, "-m", "pytest", "-q", "-m", run.marks, "--durations=10",
               f"--basetemp={basetemp}"]
    if run.workers:
        command += ["-n", str(run.workers), "--dist", "worksteal"]
    return command + extra


def await_collection(ledger: Path, processes: int, timeout: float = COLLECTION_WAIT) -> None:
    """Returns once `processes` pytest processes have written their `kept` ledger in `ledger` (their
    collection is done), or after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while len(list(ledger.glob("*.kept"))) < processes and time.monotonic() < deadline:
        time.sleep(0.2)


def run_lane(runs: list[Run], root: Path, log, extra: list[str], niceness: int = 0) -> int:
    """Runs one lane's invocations one after another, writing to `log`; the first failing exit
    code, else 0. Run N's base temporary folder is `root/runN`; its ledger is `root/ledger/runN`,
    outside it (pytest clears a base temporary folder, and the tests' own files are in it)."""
    rc = 0
    root.mkdir(parents=True, exist_ok=True)
    for index, run in enumerate(runs):
        prefix = ["nice", "-n", str(niceness)] if niceness else []
        environment = {**os.environ, LEDGER_ENV: str(root / "ledger" / f"run{index}")}
        code = subprocess.call(prefix + pytest_command(run, root / f"run{index}", run.files + extra),
                               cwd=REPO, stdout=log, stderr=subprocess.STDOUT, env=environment)
        if code == NO_TESTS:
            print(f"no tests collected for -m '{run.marks}'", file=log, flush=True)
        elif code and not rc:
            rc = code
    return rc


def main(extra: list[str]) -> int:
    cores = os.cpu_count() or 1
    whole = not extra   # the whole suite: the wall-clock lane collects only its files
    waiting = [Run("serial", 0, marked_files(("serial",)) if whole else []),
               Run("wallclock and not serial", cores, marked_files() if whole else [])]
    computing = [Run("not wallclock and not serial", cores)]
    started = time.monotonic()
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)   # inherited by every process of both lanes
    # one BLAS thread per process: each lane already runs one worker per core, and OpenBLAS's own
    # threads only contend with them (a trust-state population synthesis: 13.7 CPU-s against 8.9)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory(prefix="trustroute-suite-") as folder:
        root = Path(folder)
        (root / "cache").mkdir()
        os.environ[CACHE_ENV] = str(root / "cache")
        result: dict[str, int] = {}
        with (root / "wallclock.log").open("w+") as waiting_log:
            def waiting_lane() -> None:
                await_collection(root / "computing" / "ledger" / "run0", cores)
                result.update(rc=run_lane(waiting, root / "wallclock", waiting_log, extra))

            lane = threading.Thread(target=waiting_lane)
            lane.start()
            computing_rc = run_lane(computing, root / "computing", sys.stdout, extra, niceness=NICENESS)
            lane.join()
            waiting_log.seek(0)
            print("\n---- the wall-clock lane (serial browser session, then live and browser tests) ----")
            print(waiting_log.read(), end="", flush=True)
        waiting_rc = result["rc"]
        disagreement = lanes_disagree(root) if whole else ""
    if disagreement:
        print(f"suite: {disagreement}")
    print(f"suite: {time.monotonic() - started:.0f} s wall; exit codes: CPU-bound lane {computing_rc}, "
          f"wall-clock lane {waiting_rc}")
    return computing_rc or waiting_rc or (1 if disagreement else 0)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
