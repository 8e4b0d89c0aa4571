"""Progress bars as every command shows them (tqdm)."""

from __future__ import annotations


def bar_disable(shown: bool) -> bool | None:
    """tqdm's `disable` for a bar that is asked for (`shown`) or not: None shows it on a terminal
    only (tqdm's own test), so a log or a pipe gets no bar and an error there stays one line; True
    hides it."""
    return None if shown else True
