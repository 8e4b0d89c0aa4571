"""Small timing helpers shared by the benchmarks (the machine is noisy and shared).

`best_seconds`: best of several repeats. `paired_ratio`: a target against its baseline measured
in pairs, interleaved, in wall and CPU time, reported as the median of the per-pair ratios (load
that drifts during the run hits both members of a pair alike, and one disturbed pair moves a
median by one rank only), with the load average beside it. `TimingProcess`: a function run and
timed in a process of its own (`ForkedCalls`: any function called in one), for a pair whose
members cannot share one (libsumo runs one simulation per process: an episode that keeps its
simulation open between runs, against a bare loop that starts and closes its own).
`peak_rss_mb`: this process's own peak resident memory, and `in_spawned_process`: a function run in
a spawned process of its own, for a figure that must be that process's alone.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import statistics
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from queue import Empty
from types import TracebackType
from typing import Any, Self

ANSWER_POLL_SECONDS = 1.0   # how often `in_spawned_process` looks whether its process still runs


def peak_rss_mb() -> float:
    """This process's peak resident memory (MB): the high-water mark of its own address space
    (`VmHWM`, which an exec starts afresh). Not `ru_maxrss`: Linux keeps that across an exec, so a
    process started from a large one (`multiprocessing`'s spawn, `subprocess`) would report at
    least its parent's resident memory at the fork."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("/proc/self/status has no VmHWM line: peak memory needs Linux")


def in_spawned_process(target: Callable[..., None], *arguments: object) -> Any:
    """`target(queue, *arguments)` in a spawned process (no state of this one, its peak memory its
    own); what it puts on the queue. RuntimeError when the process ends without putting anything
    (an error it printed, or killed: a side measured for its memory may meet the out-of-memory
    killer), rather than a wait for ever."""
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    process = context.Process(target=target, args=(queue, *arguments))
    process.start()
    while True:
        ended = process.exitcode is not None   # read before the wait: what it put is then in the pipe
        try:
            result = queue.get(timeout=ANSWER_POLL_SECONDS)
            break
        except Empty:
            if ended:
                raise RuntimeError(f"the spawned process of {target.__name__} ended (exit code "
                                   f"{process.exitcode}; minus a signal's number when one killed it, "
                                   "-9 most often the out-of-memory killer) before it answered") from None
    process.join()
    return result


def best_seconds(function: Callable[[], object], repeats: int = 5) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def _timed(function: Callable[[], object]) -> tuple[float, float]:
    """(wall, CPU) seconds of one call; CPU time is this process's (libsumo runs in it)."""
    wall, cpu = time.perf_counter(), time.process_time()
    function()
    return time.perf_counter() - wall, time.process_time() - cpu


def _quartiles(values: list[float]) -> list[float]:
    low, _, high = statistics.quantiles(values, n=4, method="inclusive")
    return [low, high]


def paired_ratio(target: Callable[[], object], baseline: Callable[[], object], pairs: int = 31) -> dict:
    """Time `target` and `baseline` in this process in `pairs` interleaved pairs (see paired_timings)."""
    return paired_timings(lambda: _timed(target), lambda: _timed(baseline), pairs)


def paired_timings(target: Callable[[], tuple[float, float]], baseline: Callable[[], tuple[float, float]],
                   pairs: int = 31) -> dict:
    """Run `target` and `baseline`, each returning the (wall, CPU) seconds of one run, in `pairs`
    interleaved pairs (the order alternating within a pair, so neither always runs on a warmer
    cache); ratios are target / baseline.

    Returns medians and the minimum of each, the median and quartiles of the per-pair ratios in
    wall and in CPU time, and the 1-minute load average before and after."""
    load_before = os.getloadavg()[0]
    target_wall, target_cpu, base_wall, base_cpu = [], [], [], []
    for i in range(pairs):
        if i % 2:
            b, t = baseline(), target()
        else:
            t, b = target(), baseline()
        target_wall.append(t[0])
        target_cpu.append(t[1])
        base_wall.append(b[0])
        base_cpu.append(b[1])
    wall_ratios = [t / b for t, b in zip(target_wall, base_wall, strict=True)]
    cpu_ratios = [t / b for t, b in zip(target_cpu, base_cpu, strict=True) if b > 0]
    return {
        "pairs": pairs,
        "wall_ratio_median": statistics.median(wall_ratios), "wall_ratio_quartiles": _quartiles(wall_ratios),
        "cpu_ratio_median": statistics.median(cpu_ratios), "cpu_ratio_quartiles": _quartiles(cpu_ratios),
        "target_wall_median": statistics.median(target_wall), "target_wall_min": min(target_wall),
        "baseline_wall_median": statistics.median(base_wall), "baseline_wall_min": min(base_wall),
        "target_cpu_median": statistics.median(target_cpu), "target_cpu_min": min(target_cpu),
        "baseline_cpu_median": statistics.median(base_cpu), "baseline_cpu_min": min(base_cpu),
        "load_average_1min": [load_before, os.getloadavg()[0]],
    }


def _calls_worker(connection: Connection, function: Callable[..., object]) -> None:
    while (arguments := connection.recv()) is not None:
        connection.send(function(*arguments))


class ForkedCalls:
    """`function` in a forked process of its own: each call runs it there with the call's
    arguments and returns its result (libsumo runs one simulation per process, so two SUMO loops
    that must not share one each get a process)."""

    def __init__(self, function: Callable[..., object]) -> None:
        context = multiprocessing.get_context("fork")
        self.connection, child = context.Pipe()
        self.process = context.Process(target=_calls_worker, args=(child, function), daemon=True)
        self.process.start()
        child.close()

    def __call__(self, *arguments: object) -> Any:
        self.connection.send(arguments)
        return self.connection.recv()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.connection.send(None)
        self.process.join(10)
        if self.process.is_alive():
            self.process.kill()


class TimingProcess(ForkedCalls):
    """`function` run in a forked process of its own, one run per call, which returns the run's
    (wall, CPU) seconds measured in that process (the pipe's round trip is outside them)."""

    def __init__(self, function: Callable[[], object]) -> None:
        super().__init__(functools.partial(_timed, function))
