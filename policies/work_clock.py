"""The clock a synthesis schedules by: the wall clock, or, under a work limit, the work done.

Every deadline of a synthesis (its time limit, the shares of it its phases get, the predictions of
whether more work still fits) is a time on this clock. Without a work limit it is
time.perf_counter(), so a run stops where the wall clock says. With a work limit (`work_limit`
units, SynthesisSettings) the clock reads the units of work done so far, counted where the
searches check their deadlines (node expansions, value-iteration sweeps, propagation steps,
unfolded histories: `spend`), each unit worth WORK_UNIT_SECONDS of the scheduler's time; every
schedule then depends on the work done only, so the same problem stops at the same point on any
machine and under any load. The wall-clock time limit stays a safety net: once it has passed,
the clock reads LATE, past every deadline, and the run stops as it would at its time limit (its
result then depends on the clock; `WorkClock.timed_out` says so, and `stopped_by` names the time
limit).

The clock is ambient as time.perf_counter() is: `work_clock` installs it for the duration of one
synthesis call (the outermost one: a population synthesis' runs share it), and `now` and `spend`
read the installed one, so the routines that check a deadline need no clock argument.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

# One unit of work is worth this many seconds of the scheduler's time, so that the shares and
# predictions of a schedule keep their meaning (measured: about 100,000 units a second on one
# core of the project's 2-core test machine, for the unbounded and the population syntheses).
WORK_UNIT_SECONDS = 1e-5
# Past the wall-clock limit the clock reads this: later than every deadline a schedule makes
# (finite, so a deadline computed from it stays a number).
LATE = 1e18
# The wall-clock limit stops a run under a work limit this share early, for the work after the
# last deadline check (as the searches' own reserves do).
WALL_RESERVE = 0.04


@dataclass
class WorkClock:
    """Units of work spent against `limit` units, and the wall-clock time (time.perf_counter())
    after which the clock reads LATE."""

    limit: int
    wall_deadline: float
    spent: int = 0
    timed_out: bool = False

    def now(self) -> float:
        if not self.timed_out and time.perf_counter() >= self.wall_deadline:
            self.timed_out = True
        return LATE if self.timed_out else self.spent * WORK_UNIT_SECONDS

    @property
    def seconds(self) -> float:
        """The whole limit in the scheduler's seconds (what a synthesis takes as its time limit)."""
        return self.limit * WORK_UNIT_SECONDS


_CLOCK: ContextVar[WorkClock | None] = ContextVar("work_clock", default=None)


def now(wall: Callable[[], float] | None = None) -> float:
    """The time on the installed clock; when no work limit is installed, `wall()` (default
    time.perf_counter())."""
    clock = _CLOCK.get()
    if clock is not None:
        return clock.now()
    return time.perf_counter() if wall is None else wall()


def spend(units: int) -> None:
    """Count `units` of work on the installed clock (nothing without a work limit)."""
    clock = _CLOCK.get()
    if clock is not None:
        clock.spent += int(units)


def installed() -> WorkClock | None:
    """The clock of the synthesis call under way, if it has a work limit."""
    return _CLOCK.get()


@contextmanager
def work_clock(work_limit: int | None, time_limit: float) -> Iterator[float]:
    """Install a WorkClock of `work_limit` units for the block, unless one is installed already
    (an outer call's) or there is no work limit; yields the time limit to schedule by: the work
    limit in the scheduler's seconds when a clock is installed here, else `time_limit` (an outer
    call's share, already on its clock; or seconds on the wall clock)."""
    if work_limit is None or _CLOCK.get() is not None:
        yield time_limit
        return
    clock = WorkClock(limit=work_limit,
                      wall_deadline=time.perf_counter() + (1.0 - WALL_RESERVE) * time_limit)
    token = _CLOCK.set(clock)
    try:
        yield clock.seconds
    finally:
        _CLOCK.reset(token)


# What of a method's own can end a synthesis unconverged before its limits (`stopped_by`'s `cap`):
# its cluster policies' largest cap (policies/synthesis/cluster_policy.py); the whole schedule of an
# unbounded belief-MDP synthesis, run to its end ("depth cap", policies/synthesis/belief_synthesis.py,
# UNBOUNDED_HORIZONS and the cluster rounds); the nodes per level of
# the trust-state search and of its evaluations, their dropped live mass unknown; the junctions of
# an unbounded evaluation (UNBOUNDED_MAX_LEVELS, policies/evaluation/trust_state.py); the fixed
# depths of the trust-state synthesis' unbounded searches and policy horizons; its allowance for
# rounding when every search is exact and tau is below it (policies/trust_state_synthesis/
# synthesis.py, JOINT_STOPS); the robust population objective's grid of candidate priors, every one
# run and no run cut by a limit ("candidate grid", policies/synthesis/population.py: a grid search,
# not an optimisation over all policies, so its gap is the grid's own).
CAPS = ("cluster cap", "node cap", "junction cap", "depth cap", "rounding margin", "candidate grid")
# The limits that can end a synthesis (`stopped_by`): more work or more time could move its bounds.
LIMITS = ("work limit", "time limit")


def limit_reached(clock: WorkClock | None) -> str:
    """The limit a deadline on `clock` stands for (one of LIMITS): the work limit while the clock
    counts work, the time limit without a work limit or once the wall clock has passed it."""
    return "work limit" if clock is not None and not clock.timed_out else "time limit"


def stopped_by(converged: bool, clock: WorkClock | None, node_budget: bool = False,
               cap: str | None = None) -> str:
    """Which limit ended a synthesis (or the evaluation of its policy): "time limit" when a run
    under a work limit reached the wall clock, whatever else it reached (past it every deadline
    read LATE: a run, a search or an evaluation may have been cut where the work limit would not
    have, so its result depends on the machine); else "convergence" (the gap reached tau), "node
    budget" (its search stopped at its node budget, `node_budget`, before any limit), `cap` (one of
    CAPS: its bounds are those its own cap left) or the limit its deadlines stood for
    (`limit_reached`: "work limit" or "time limit")."""
    if cap is not None and cap not in CAPS:
        raise ValueError(f"unknown cap {cap!r}: one of {CAPS}")
    if clock is not None and clock.timed_out:
        return "time limit"
    if converged:
        return "convergence"
    if node_budget:
        return "node budget"
    if cap is not None:
        return cap
    return limit_reached(clock)
