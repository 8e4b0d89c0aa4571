"""Run the whole suite the way `make test` does: `python -m tests.suite [PYTEST_ARGS...]`.

Two lanes run at once. The tests whose outcome depends on the wall clock (marked `wallclock`: a
live station paced in real time, a browser driven as a person would, a peer's wall-clock time
limit) mostly wait, and fail if starved of a core, so they run at normal priority: first the
`serial` browser session alone in its lane, then the other `wallclock` tests on one pytest-xdist
worker per core. The CPU-bound rest runs meanwhile at a lower priority (`nice`), on one worker per
core with work stealing, and takes every cycle the waiting lane leaves. Both lanes share one cache
root for nets and policies (tests/conftest.py, `temporary_cache`), so a policy one lane builds the
other reads. The exit code is the first lane's that failed; a lane that collects nothing is not a
failure (pytest's exit code 5)."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
NO_TESTS = 5      # pytest: nothing collected
NICENESS = 10     # the CPU-bound lane's: a paced test that wants its core gets about 90 % of it
CACHE_ENV = "TRUSTROUTE_TEST_CACHE"   # the cache root of every run (tests/conftest.py reads it)


@dataclass(frozen=True)
class Run:
    """One pytest invocation of a lane: its marker expression and its worker count (0: in process)."""
    marks: str
    workers: int


def pytest_command(run: Run, basetemp: Path, extra: list[str]) -> list[str]:
    command = [sys.executable, "-m", "pytest", "-q", "-m", run.marks, "--durations=10",
               f"--basetemp={basetemp}"]
    if run.workers:
        command += ["-n", str(run.workers), "--dist", "worksteal"]
    return command + extra


def run_lane(runs: list[Run], root: Path, log, extra: list[str], niceness: int = 0) -> int:
    """Runs one lane's invocations one after another, writing to `log`; the first failing exit
    code, else 0."""
    rc = 0
    root.mkdir(parents=True, exist_ok=True)
    for index, run in enumerate(runs):
        prefix = ["nice", "-n", str(niceness)] if niceness else []
        code = subprocess.call(prefix + pytest_command(run, root / f"run{index}", extra), cwd=REPO,
                               stdout=log, stderr=subprocess.STDOUT)
        if code == NO_TESTS:
            print(f"no tests collected for -m '{run.marks}'", file=log, flush=True)
        elif code and not rc:
            rc = code
    return rc


def main(extra: list[str]) -> int:
    cores = os.cpu_count() or 1
    waiting = [Run("serial", 0), Run("wallclock and not serial", cores)]
    computing = [Run("not wallclock and not serial", cores)]
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="trustroute-suite-") as folder:
        root = Path(folder)
        (root / "cache").mkdir()
        os.environ[CACHE_ENV] = str(root / "cache")
        result: dict[str, int] = {}
        with (root / "wallclock.log").open("w+") as waiting_log:
            lane = threading.Thread(target=lambda: result.update(
                rc=run_lane(waiting, root / "wallclock", waiting_log, extra)))
            lane.start()
            computing_rc = run_lane(computing, root / "computing", sys.stdout, extra, niceness=NICENESS)
            lane.join()
            waiting_log.seek(0)
            print("\n---- the wall-clock lane (serial browser session, then live and browser tests) ----")
            print(waiting_log.read(), end="", flush=True)
        waiting_rc = result["rc"]
    print(f"suite: {time.monotonic() - started:.0f} s wall; exit codes: CPU-bound lane {computing_rc}, "
          f"wall-clock lane {waiting_rc}")
    return computing_rc or waiting_rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
