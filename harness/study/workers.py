"""The local process pool of a study: one task per worker at a time, workers that die with the parent.

`ProcessPoolExecutor` marks every pending task as failed when one worker dies (the pool is
"broken"), and its workers outlive a parent killed by SIGKILL or SIGTERM, blocked on a pipe. This
pool instead gives each worker one task at a time over its own pipe, so the parent always knows
which task a worker was running:

- a worker that dies (killed, out of memory, a crash in native code) fails only the task it was
  running, with the reason (signal or exit code); a fresh worker takes its place;
- workers die with their parent: `prctl(PR_SET_PDEATHSIG, SIGKILL)` on Linux, and a watchdog
  thread that polls the parent pid wherever prctl is unavailable (and for the moment between
  fork and prctl);
- the pool is shut down (workers terminated, then killed) whenever the parent leaves the
  generator: normal end, an exception, or SIGTERM turned into an exception by `sigterm_raises`.
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
from types import FrameType
from typing import Any, Generic, TypeVar

PR_SET_PDEATHSIG = 1
PARENT_POLL_SECONDS = 0.5
SHUTDOWN_SECONDS = 2.0

Task = TypeVar("Task")
Result = TypeVar("Result")


class Terminated(KeyboardInterrupt):
    """SIGTERM received: unwinds like Ctrl-C so every pool is shut down on the way out."""


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block, SIGTERM raises `Terminated` in the main thread (no-op elsewhere)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:  # noqa: ARG001 - the signal API's signature
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


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


def _worker_main(function: Callable[[Any], object], connection: Connection, parent_pid: int) -> None:
    die_with_parent(parent_pid)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    while True:
        try:
            task = connection.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        connection.send(function(task))


def describe_exit(exitcode: int | None) -> str:
    if exitcode is None:
        return "did not exit"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


class _Worker(Generic[Task]):
    def __init__(self, context: DefaultContext, function: Callable[[Task], object]) -> None:
        self.connection, child = context.Pipe()
        self.process = context.Process(target=_worker_main, args=(function, child, os.getpid()), daemon=True)
        self.process.start()
        child.close()
        self.task: Task | None = None

    def stop(self) -> None:
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
    pool = [_Worker(context, function) for _ in range(min(workers, len(tasks)))]
    try:
        while pending or any(w.task is not None for w in pool):
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
                    worker.task = None
                    pool[pool.index(worker)] = _Worker(context, function)
                    worker.connection.close()
                    yield died(task, f"worker process {describe_exit(worker.process.exitcode)}")
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
