"""The local process pool of a study: one task per worker at a time, workers that die with the parent.

`ProcessPoolExecutor` marks every pending task as failed when one worker dies (the pool is
"broken"), and its workers outlive a parent killed by SIGKILL or SIGTERM, blocked on a pipe. This
pool instead gives each worker one task at a time over its own pipe, so the parent always knows
which task a worker was running:

- a worker that dies (killed, out of memory, a crash in native code) fails only the task it was
  running, with the reason (signal or exit code); a fresh worker takes its place while tasks wait;
- workers die with their parent: `prctl(PR_SET_PDEATHSIG, SIGKILL)` on Linux, and a watchdog
  thread that polls the parent pid wherever prctl is unavailable (and for the moment between
  fork and prctl); a forkserver's workers die with the fork server, which ends with the parent;
- the workers are started inside the pool's shutdown, so a Ctrl-C while they start stops those
  already started;
- the pool is shut down (workers terminated, then killed) whenever the parent leaves the
  generator: normal end, an exception, or SIGTERM turned into an exception by `sigterm_raises`
  (trustroute/core/interrupts.py);
- workers that exit before they are ready, twice in a row, stop the pool with `WorkersCannotStart`
  rather than failing every task one spawned worker at a time. Where workers are spawned, each
  imports the main script again: a script that runs a study outside an
  `if __name__ == "__main__":` guard makes every worker exit while it starts.

Where workers are spawned, the task function (with the study's context) is sent over the worker's
own pipe once it runs, not as the process's arguments: CPython writes those to the new process
while it keeps the pipe's reading end open itself, so a worker that exits before reading them all
(they exceed a pipe's buffer) would block the parent for ever. Forked workers inherit the
function, and nothing is sent. A pool starts all its workers before it hands any of them the
function: a send waits until its worker has imported what it needs (seconds) and read it, so
workers started one after the other's send would import one after the other. A worker that dies is
replaced at the pool's next round, once every death seen with it is counted, and only if a task
waits for it; START_FAILURES workers ending in a row before they are ready stop the pool. A worker
stopped before it was handed the function is not sent the stop word (it would take it for the
function): its pipe is closed, and it returns at the end of the pipe.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from multiprocessing.connection import Connection
from multiprocessing.context import DefaultContext
from typing import Any, Generic, TypeVar

from trustroute.core.errors import InputError

PR_SET_PDEATHSIG = 1
PARENT_POLL_SECONDS = 0.5
SHUTDOWN_SECONDS = 2.0
# Workers exiting before they are ready this many times in a row stop the pool: one may be a
# transient failure (a process killed for memory while it imports), two are the rule.
START_FAILURES = 2

Task = TypeVar("Task")
Result = TypeVar("Result")


class Ready:
    """A worker's first message: it runs and holds the task function."""


# Where a worker that ended while it started said why: one that exited (a Python error) printed it;
# one killed by a signal printed nothing, and SIGKILL there is most often the out-of-memory killer.
EXITED_SAID = "printed its error above"
KILLED_SAID = ("a process killed by a signal prints no error: the kernel's log (dmesg) says whether the "
               "out-of-memory killer killed it")
EXITED_FIX = ('a script that calls run_study must call it under `if __name__ == "__main__":`, since '
              "spawned workers import the script again; otherwise see the workers' errors, or run with "
              "one worker (--workers 1)")
KILLED_FIX = "give the workers more memory, or run fewer of them (--workers 1)"


class WorkersCannotStart(InputError):
    """Worker processes exit before they are ready, again and again: `exitcodes`, theirs in order
    (`multiprocessing.Process.exitcode`: minus the signal for a worker killed by one)."""

    def __init__(self, exitcodes: list[int | None]) -> None:
        exited = [code is not None and code >= 0 for code in exitcodes]
        killed = [code is not None and code < 0 for code in exitcodes]
        ends = ", then ".join(dict.fromkeys(describe_exit(code) for code in exitcodes))
        said = [f"{ends}, {len(exitcodes)} in a row"]
        if any(exited):
            said.append(f"each {EXITED_SAID}" if all(exited) else f"each that exited {EXITED_SAID}")
        if any(killed):
            said.append(KILLED_SAID)
        fixes = ([KILLED_FIX] if any(killed) else []) + ([] if all(killed) else [EXITED_FIX])
        super().__init__("study workers", "",
                         f"worker processes exit while they start (worker process {'; '.join(said)})",
                         "; ".join(fixes))


def die_with_parent(parent_pid: int) -> None:
    """Make this process exit when `parent_pid` does (called first thing in every worker)."""
    armed = False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        armed = libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        armed = False
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)
    if not armed:
        def watch() -> None:
            while True:
                time.sleep(PARENT_POLL_SECONDS)
                if os.getppid() != parent_pid:
                    os._exit(1)

        threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def _worker_main(function: Callable[[Any], object] | None, connection: Connection,
                 parent_pid: int | None) -> None:
    # a forkserver's worker is the fork server's child, not the study's: it dies with the server,
    # which ends when the study's process does
    die_with_parent(parent_pid if parent_pid is not None else os.getppid())
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if function is None:   # spawned: the function comes over the pipe (the module's docstring)
        try:
            function = connection.recv()
        except (EOFError, OSError):
            return
    connection.send(Ready())
    while True:
        try:
            task = connection.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        connection.send(function(task))


def describe_exit(exitcode: int | None) -> str:
    if exitcode is None:   # its pipe closed, yet the process still ran SHUTDOWN_SECONDS later
        return f"closed its pipe and had not exited {SHUTDOWN_SECONDS:g} s later"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


class _Worker(Generic[Task]):
    def __init__(self, context: DefaultContext, function: Callable[[Task], object]) -> None:
        self.connection, child = context.Pipe()
        method = context.get_start_method()
        forked = method == "fork"
        arguments = (function if forked else None, child, None if method == "forkserver" else os.getpid())
        self.process = context.Process(target=_worker_main, args=arguments, daemon=True)
        self.process.start()
        child.close()
        self.unsent = None if forked else function   # what `hand` sends
        self.task: Task | None = None
        self.ready = False

    def hand(self) -> None:
        """Send a spawned worker its task function (the module's docstring); a forked one has it."""
        function, self.unsent = self.unsent, None
        if function is None:
            return
        try:
            with contextlib.suppress(OSError):   # it exited already: its pipe's end is seen closed
                self.connection.send(function)
        except BaseException:   # a Ctrl-C mid-send: the pipe holds part of a message, so it is killed
            self.process.kill()
            self.process.join()
            raise

    def stop(self) -> None:
        if self.unsent is None:   # it has its function: None is the stop word between tasks
            with contextlib.suppress(OSError, ValueError):
                self.connection.send(None)
        self.connection.close()


def process_pool(
    function: Callable[[Task], Result], tasks: list[Task], workers: int, died: Callable[[Task, str], Result]
) -> Iterator[Result]:
    """Yield `function(task)` for every task, as they complete, on `workers` processes.

    A task whose worker died yields `died(task, reason)` instead (e.g. a failed outcome)."""
    context = multiprocessing.get_context()
    pending = deque(tasks)
    size = min(workers, len(tasks))
    pool: list[_Worker[Task]] = []
    start_failures: list[int | None] = []   # exit codes of workers ended before they were ready, in a row
    try:
        while pending or any(w.task is not None for w in pool):
            # started inside the try, each into the pool at once: a Ctrl-C while workers start or
            # are handed the function shuts down those already started
            fresh = len(pool)
            while len(pool) < size and len(pending) > sum(w.task is None for w in pool):
                pool.append(_Worker(context, function))
            for worker in pool[fresh:]:
                worker.hand()
            for worker in pool:
                if worker.task is None and pending:
                    worker.task = pending.popleft()
                    try:
                        worker.connection.send(worker.task)
                    except OSError:
                        pass  # it died idle; the wait below sees its pipe closed
            # keyed by object: wait returns the connections it is given, typed as any waitable
            busy: dict[object, tuple[_Worker[Task], Task]] = {
                w.connection: (w, w.task) for w in pool if w.task is not None}
            for connection in multiprocessing.connection.wait([w.connection for w, _ in busy.values()]):
                worker, task = busy[connection]
                try:
                    result = worker.connection.recv()
                except (EOFError, OSError):
                    worker.process.join(SHUTDOWN_SECONDS)
                    reason = f"worker process {describe_exit(worker.process.exitcode)}"
                    start_failures = [] if worker.ready else [*start_failures, worker.process.exitcode]
                    if len(start_failures) >= START_FAILURES:
                        raise WorkersCannotStart(start_failures) from None
                    pool.remove(worker)   # replaced at the loop's top if a task waits for it
                    worker.connection.close()
                    yield died(task, reason)
                    continue
                if isinstance(result, Ready):
                    worker.ready = True
                    start_failures = []
                    continue
                worker.task = None
                yield result
    finally:
        shutdown(pool)


def shutdown(pool: list[_Worker[Task]]) -> None:
    """Stop every worker: ask, then SIGTERM, then SIGKILL; never leaves one behind."""
    for worker in pool:
        worker.stop()
    deadline = time.monotonic() + SHUTDOWN_SECONDS
    for worker in pool:
        worker.process.join(max(0.0, deadline - time.monotonic()))
    for worker in pool:
        if worker.process.is_alive():
            worker.process.terminate()
            worker.process.join(SHUTDOWN_SECONDS)
        if worker.process.is_alive():
            worker.process.kill()
            worker.process.join()
