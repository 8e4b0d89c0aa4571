"""SIGTERM ends a run the way Ctrl-C does.

A process stopped with SIGTERM (a service manager, `kill`, a batch scheduler) should leave what
Ctrl-C leaves: every `finally` and context manager runs (a study's pool is shut down, a live
study closed, a temporary file removed) and the command ends with its one "interrupted" line
(harness/cli.py). SIGTERM's default action kills the process at once, so within `sigterm_raises`
it raises `Terminated`, a KeyboardInterrupt, instead. A process started with SIGTERM ignored (its
parent's choice, which an exec keeps) goes on ignoring it, as Python leaves an ignored SIGINT
ignored rather than make it a KeyboardInterrupt.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType


class Terminated(KeyboardInterrupt):
    """SIGTERM received: unwinds like Ctrl-C."""


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Within the block, SIGTERM raises `Terminated` in the main thread (no-op elsewhere: only the
    main thread can set a signal's handler; and where SIGTERM is ignored)."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGTERM) is signal.SIG_IGN):
        yield
        return

    def handler(signum: int, frame: FrameType | None) -> None:  # noqa: ARG001 - the signal API's signature
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
