"""trustroute/core/interrupts.py: within `sigterm_raises` SIGTERM unwinds as Ctrl-C does, unless
the process was started with SIGTERM ignored, which it then keeps ignoring (as Python keeps an
ignored SIGINT from becoming a KeyboardInterrupt)."""

from __future__ import annotations

import os
import signal
import time

import pytest

from trustroute.core.interrupts import Terminated, sigterm_raises


def _signalled() -> None:
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(0.5)   # the handler runs at the next bytecode boundary: the sleep is cut short by it


def test_sigterm_raises_terminated_within_the_block_and_not_after():
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Terminated), sigterm_raises():
        _signalled()
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_process_started_with_sigterm_ignored_keeps_ignoring_it():
    previous = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        with sigterm_raises():
            _signalled()   # ignored: no Terminated, the block runs to its end
            assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    except Terminated:
        pytest.fail("a SIGTERM the process was started to ignore raised Terminated")
    finally:
        signal.signal(signal.SIGTERM, previous)
