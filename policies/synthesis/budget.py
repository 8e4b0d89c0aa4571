"""The time-budget scheduler of every synthesis: a deadline on the synthesis' clock, deadlines for
shares of the time limit or of the time left, and whether work of a predicted length still fits.
The clock is time.perf_counter(), or under a work limit the work done (policies/work_clock.py):
every time here is on it, but `elapsed`, the wall-clock seconds a run reports.

Searches check their deadline as they go and keep a reserve of the limit for the work after the
last check (the final backup, the policy table, the statistics), so that a call ends within its
time limit. Lower-level routines take a plain deadline (a time on the clock) and make a budget of
it (`TimeBudget.until`) where they need shares or fit checks. The several runs of one population
synthesis share one budget by a RunSchedule.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

from trustroute.core.wording import interval
from trustroute.policies.work_clock import LIMITS, installed, limit_reached
from trustroute.policies.work_clock import now as clock_now

MIN_RUN_SECONDS = 0.05  # a run's share never below this: a search needs a first expansion
# A run given MIN_RUN_SECONDS takes up to about this many times as long: its fixed costs (the
# abstraction, the table) come before its first deadline check (measured: 0.05-0.18 s on the
# packaged town at H = 20).
LATER_RUN_FACTOR = 3.0


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


@dataclass
class RunSchedule:
    """The runs of one population synthesis under one TimeBudget: by default each run's time limit
    is an equal share of the time left among the runs still to come, after the work between runs
    (the exact per-type evaluations, at their mean cost so far) is set aside for the gaps to come;
    a run may be given a larger share of the time left (`next_limit`)."""

    budget: TimeBudget
    runs: int
    done: int = 0
    on_phase: Callable[[str], None] | None = None
    last_end: float | None = None
    between: float = 0.0  # seconds spent between runs so far
    gaps: int = 0
    not_needed: int = 0   # candidate priors left out once the best was within tau of the bound
    skipped: int = 0      # candidate priors left out for want of time
    cut: int = 0          # runs that ended at their limit unconverged (`finished`)
    at_node_budget: int = 0   # runs whose search stopped at its node budget, before any limit

    def _close_gap(self) -> None:
        """Count the work since the last run ended (its evaluations) as one gap between runs."""
        if self.last_end is not None:
            self.between += clock_now() - self.last_end
            self.gaps += 1
            self.last_end = None

    @property
    def per_gap(self) -> float:
        return self.between / self.gaps if self.gaps else 0.0

    def left(self) -> float:
        """Seconds left for the runs still to come, the gaps after them set aside."""
        self._close_gap()
        remaining = max(self.runs - self.done, 1)
        return max(self.budget.deadline - clock_now() - self.per_gap * remaining, 0.0)

    def next_limit(self, share: float = 0.0, at_least: float = 0.0) -> float:
        """The next run's limit: the larger of an equal share, `share` of the time left and
        `at_least` seconds, never more than the time to the deadline less the run's own following
        work (the runs after it may be skipped), and never below MIN_RUN_SECONDS."""
        left = self.left()
        remaining = max(self.runs - self.done, 1)
        own = max(self.budget.deadline - clock_now() - self.per_gap, 0.0)
        return max(min(max(left / remaining, share * left, at_least), own), MIN_RUN_SECONDS)

    def capped_limit(self, share: float) -> float:
        """An equal share of the time left, at most `share` of it."""
        left = self.left()
        return max(min(left / max(self.runs - self.done, 1), share * left), MIN_RUN_SECONDS)

    def affords(self, later_runs: int, seconds: float = MIN_RUN_SECONDS) -> bool:
        """Whether one more run of `seconds` with its following work still fits before the
        deadline, with `later_runs` runs after it that must run."""
        self._close_gap()
        return self.budget.fits(self.per_gap + seconds + MIN_RUN_SECONDS * later_runs)

    def skip(self, what: str) -> None:
        """A run left out for want of time (a candidate prior): the stderr line names the limit
        that leaves it none (work_clock.limit_reached)."""
        self.runs -= 1
        self.skipped += 1
        if self.on_phase is not None:
            self.on_phase(f"[{self.budget.elapsed():.1f} s] {what}: skipped, too little of the "
                          f"{limit_reached(installed())} is left for its run")

    def settle(self, left_out: int) -> None:
        """The last `left_out` candidate priors left out: the best candidate so far is within tau
        of the robust bound."""
        self.runs -= left_out
        self.not_needed += left_out
        if self.on_phase is not None:
            self.on_phase(f"[{self.budget.elapsed():.1f} s] the best candidate's worst type is within "
                          f"tau of the robust bound: the other {left_out} candidate priors are not run")

    def evaluation_deadline(self, later_runs: int) -> float:
        """The deadline of the exact evaluations after a run: the call's, less the shortest share
        of the `later_runs` runs that must still come (the per-type bounds), each allowed
        LATER_RUN_FACTOR times its share for its fixed costs."""
        return self.budget.deadline - LATER_RUN_FACTOR * MIN_RUN_SECONDS * later_runs

    def finished(self, what: str, lower: float, upper: float, ended: str) -> None:
        """A run ended with bounds [lower, upper], for the reason `ended` (work_clock.stopped_by's
        word for it; one of LIMITS: at its limit, unconverged, so a longer limit could have moved
        them)."""
        self.done += 1
        self.cut += ended in LIMITS
        self.at_node_budget += ended == "node budget"
        self.last_end = clock_now()
        if self.on_phase is not None:
            self.on_phase(f"[{self.done}/{self.runs}, {self.budget.elapsed():.1f} s] {what}: "
                          f"{interval(lower, upper)}")
