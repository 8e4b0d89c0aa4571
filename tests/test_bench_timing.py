"""benchmarks/timing.py: a process started from a large one reports its own peak memory, not its
parent's (the peer table, bench_storm, bench_city and bench_synthesis_scaling run each side so)."""

from __future__ import annotations

import json
import subprocess
import sys

from benchmarks.timing import in_spawned_process, peak_rss_mb

PARENT_MB = 400


def _report_peak(queue) -> None:
    queue.put(peak_rss_mb())


def _held(megabytes: int) -> bytearray:
    block = bytearray(megabytes * 1024 * 1024)
    block[::4096] = b"\1" * len(range(0, len(block), 4096))   # every page resident
    return block


def test_a_spawned_process_reports_its_own_peak_memory_not_its_parents():
    held = _held(PARENT_MB)
    assert peak_rss_mb() >= PARENT_MB
    child = in_spawned_process(_report_peak)
    assert 0 < child < PARENT_MB / 2, f"the spawned process reports {child:.0f} MB"
    del held


def test_a_subprocess_reports_its_own_peak_memory_not_its_parents():
    held = _held(PARENT_MB)
    done = subprocess.run([sys.executable, "-c", "import json; from benchmarks.timing import peak_rss_mb; "
                           "print(json.dumps(peak_rss_mb()))"], capture_output=True, text=True, check=True)
    child = json.loads(done.stdout)
    assert 0 < child < PARENT_MB / 2, f"the subprocess reports {child:.0f} MB"
    del held


def _dies(queue) -> None:
    import os

    os._exit(3)   # as a side killed by the out-of-memory killer ends: nothing on the queue


def test_a_spawned_process_that_dies_before_it_answers_is_an_error_not_a_hang():
    import threading

    import pytest

    outcome: list[BaseException | object] = []

    def run() -> None:
        try:
            outcome.append(in_spawned_process(_dies))
        except RuntimeError as error:
            outcome.append(error)

    waiting = threading.Thread(target=run, daemon=True)
    waiting.start()
    waiting.join(60)
    assert not waiting.is_alive(), "in_spawned_process still waits for a process that has ended"
    [error] = outcome
    assert isinstance(error, RuntimeError) and "exit code 3" in str(error), error
    with pytest.raises(RuntimeError, match="_dies"):
        in_spawned_process(_dies)
