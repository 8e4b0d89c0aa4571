"""Our side of a peer comparison within a time limit (`our_bounds` of trustroute/app/peers.py,
`trustroute peer storm|paynt --our-time-limit`): wherever the limit stops our search, its bounds
hold the bounds of the search run to its end, and it says that a limit stopped it.

The limits are put on a work clock (policies/work_clock.py), so each stops the search at the same
point on any machine and under any load; a deadline on that clock stands for the work limit, so the
search names it (`"work limit"`; on the wall clock, as from the command line, `"time limit"`:
tests/harness/test_peer_cli.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.app.peers import DEFAULT_MAX_NODES, LIMITS, ComparedProblem, loaded_problem, our_bounds
from trustroute.policies.work_clock import WORK_UNIT_SECONDS, installed, work_clock

# The installed clock's own limits are out of reach: only our time limit can stop the search.
NO_WORK_LIMIT = 10**12
SAFETY_SECONDS = 600.0


@pytest.fixture(scope="module")
def problem():
    """(spec, POMDP) of φ1 with the trust-state atom on the paper's town, as the command loads it."""
    return loaded_problem(ComparedProblem("specs/phi1_trust.toml"))


def on_work_clock(problem, horizon: int | None, depth: int, max_nodes: int, seconds: float | None):
    """`our_bounds` within `seconds` on a work clock, and the units of work it spent."""
    spec, pomdp = problem
    with work_clock(NO_WORK_LIMIT, SAFETY_SECONDS):
        bounds = our_bounds(pomdp, spec, horizon, depth, max_nodes, time_limit=seconds)
        spent = installed().spent
    return bounds, spent


def contains(outer, inner) -> bool:
    return outer.lower <= inner.lower and outer.upper >= inner.upper


def test_a_limit_short_of_the_search_stops_it_with_bounds_that_hold_the_full_ones(problem):
    """Within 10 junctions the search ends exact, after about 10.6 s on the work clock (1.06 million
    units); limits of 0.2 to 3.4 s stop it before its last levels, and each result holds the exact
    value, is wider than it and names the limit; run again, it is the same."""
    full, spent = on_work_clock(problem, 10, 10, DEFAULT_MAX_NODES, None)
    assert full.stopped_by == "convergence" and full.cut_nodes == 0 and full.gap <= 1e-11
    for seconds in (0.2, 1.3, 3.4):
        assert seconds < spent * WORK_UNIT_SECONDS
        limited, _ = on_work_clock(problem, 10, 10, DEFAULT_MAX_NODES, seconds)
        assert limited.stopped_by == "work limit", seconds
        assert contains(limited, full), (seconds, limited, full)
        assert limited.nodes < full.nodes and limited.cut_nodes > 0 and limited.gap > full.gap
    again, _ = on_work_clock(problem, 10, 10, DEFAULT_MAX_NODES, 3.4)
    assert (again.lower, again.upper, again.nodes) == (limited.lower, limited.upper, limited.nodes)


def test_the_search_names_the_limit_wherever_it_moved_the_bounds(problem):
    """The unbounded objective to 6 junctions with 100 nodes a level (its cut nodes and those at the
    depth valued by the open-loop continuation, 30 junctions each), under limits from 2% to 120% of
    the work it takes: each result overlaps the full one (both hold Pr_max; the full one is not
    exact here, so a limited lower bound may be above its own) and names its cap only with the full
    one's bounds. Here, where the limit stopped it, its bounds differ from the full one's and it
    names the limit, also where it stopped only the valuing of leaves after every level was made."""
    full, spent = on_work_clock(problem, None, 6, 100, None)
    assert full.stopped_by == "node cap"
    named, valuing_cut = set(), 0
    for fraction in np.linspace(0.02, 1.2, 60):
        limited, _ = on_work_clock(problem, None, 6, 100, float(fraction * spent * WORK_UNIT_SECONDS))
        assert limited.lower <= full.upper and limited.upper >= full.lower, (fraction, limited, full)
        moved = (limited.lower, limited.upper) != (full.lower, full.upper)
        assert (limited.stopped_by in LIMITS) == moved, (fraction, limited, full)
        assert limited.stopped_by == ("work limit" if moved else "node cap")
        named.add(limited.stopped_by)
        valuing_cut += moved and limited.nodes == full.nodes
    assert named == {"work limit", "node cap"} and valuing_cut > 0
