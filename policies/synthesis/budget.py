"""The time-budget scheduler of every synthesis: a deadline on time.perf_counter(), deadlines for
shares of the time limit or of the time left, and whether work of a predicted length still fits.

Searches check their deadline as they go and keep a reserve of the limit for the work after the
last check (the final backup, the policy table, the statistics), so that a call ends within its
time limit. Lower-level routines take a plain deadline (a perf_counter time) and make a budget of
it (`TimeBudget.until`) where they need shares or fit checks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace


@dataclass(frozen=True)
class TimeBudget:
    """From `started` to `deadline` (time.perf_counter() seconds); shares are of `limit` seconds."""

    started: float
    deadline: float
    limit: float

    @classmethod
    def start(cls, limit: float, reserve: float = 0.0) -> TimeBudget:
        """A budget of `limit` seconds from now whose deadline keeps `reserve` of it back."""
        now = time.perf_counter()
        return cls(started=now, deadline=now + (1.0 - reserve) * limit, limit=limit)

    @classmethod
    def until(cls, deadline: float) -> TimeBudget:
        """A budget from now to `deadline`."""
        now = time.perf_counter()
        return cls(started=now, deadline=deadline, limit=deadline - now)

    def share(self, fraction: float) -> float:
        """The deadline of the first `fraction` of the limit, never past the deadline."""
        return min(self.deadline, self.started + fraction * self.limit)

    def share_of_rest(self, fraction: float, until: float | None = None) -> float:
        """The deadline of `fraction` of the time left before `until` (default: the deadline)."""
        now = time.perf_counter()
        end = self.deadline if until is None else until
        return now + fraction * max(end - now, 0.0)

    def fits(self, seconds: float, until: float | None = None) -> bool:
        """Whether work predicted to take `seconds` from now ends before `until` (default: the
        deadline)."""
        end = self.deadline if until is None else until
        return time.perf_counter() + seconds < end

    def expired(self, until: float | None = None) -> bool:
        """Whether `until` (default: the deadline) has come."""
        return time.perf_counter() >= (self.deadline if until is None else until)

    def elapsed(self) -> float:
        """Seconds since the start."""
        return time.perf_counter() - self.started

    def ending(self, deadline: float) -> TimeBudget:
        """The same start and limit with another deadline."""
        return replace(self, deadline=deadline)
