"""The time-budget scheduler of every synthesis: a deadline on the synthesis' clock, deadlines for
shares of the time limit or of the time left, and whether work of a predicted length still fits.
The clock is time.perf_counter(), or under a work limit the work done (policies/work_clock.py):
every time here is on it, but `elapsed`, the wall-clock seconds a run reports.

Searches check their deadline as they go and keep a reserve of the limit for the work after the
last check (the final backup, the policy table, the statistics), so that a call ends within its
time limit. Lower-level routines take a plain deadline (a time on the clock) and make a budget of
it (`TimeBudget.until`) where they need shares or fit checks.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

from trustroute.policies.work_clock import now as clock_now


@dataclass(frozen=True)
class TimeBudget:
    """From `started` to `deadline` (times on the clock); shares are of `limit` seconds. `wall_started`:
    time.perf_counter() at the start, for the seconds a run reports."""

    started: float
    deadline: float
    limit: float
    wall_started: float = field(default_factory=time.perf_counter)

    @classmethod
    def start(cls, limit: float, reserve: float = 0.0) -> TimeBudget:
        """A budget of `limit` seconds from now whose deadline keeps `reserve` of it back."""
        now = clock_now()
        return cls(started=now, deadline=now + (1.0 - reserve) * limit, limit=limit)

    @classmethod
    def until(cls, deadline: float) -> TimeBudget:
        """A budget from now to `deadline`."""
        now = clock_now()
        return cls(started=now, deadline=deadline, limit=deadline - now)

    def share(self, fraction: float) -> float:
        """The deadline of the first `fraction` of the limit, never past the deadline."""
        return min(self.deadline, self.started + fraction * self.limit)

    def share_of_rest(self, fraction: float, until: float | None = None) -> float:
        """The deadline of `fraction` of the time left before `until` (default: the deadline)."""
        now = clock_now()
        end = self.deadline if until is None else until
        return now + fraction * max(end - now, 0.0)

    def fits(self, seconds: float, until: float | None = None) -> bool:
        """Whether work predicted to take `seconds` from now ends before `until` (default: the
        deadline)."""
        end = self.deadline if until is None else until
        return clock_now() + seconds < end

    def expired(self, until: float | None = None) -> bool:
        """Whether `until` (default: the deadline) has come."""
        return clock_now() >= (self.deadline if until is None else until)

    def elapsed(self) -> float:
        """Wall-clock seconds since the start (what a run reports)."""
        return time.perf_counter() - self.wall_started

    def used(self) -> float:
        """The clock's seconds since the start (what a schedule predicts from)."""
        return clock_now() - self.started

    def ending(self, deadline: float) -> TimeBudget:
        """The same start and limit with another deadline."""
        return replace(self, deadline=deadline)
