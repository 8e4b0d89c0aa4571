"""`trustroute peer storm SPEC`: Storm's bounds beside ours on the same product POMDP.

For specs whose atoms are all roads and trust-state atoms (docs/trust_states.md). Storm runs
belief unfolding (lower bound, at most --time-limit seconds of exploration) and belief
discretisation (upper bound, at --resolution) on the exported product; ours is the search over
joint beliefs of policies/trust_state_synthesis/search.py (exact for --horizon H; for the unbounded objective
to --depth junctions with relaxation bounds at the leaves). `trustroute peer paynt SPEC` runs
PAYNT's finite-state controller synthesis on the same product: the value of the controller it
finds is a lower bound of Pr_max (policies/peer/paynt.py). `trustroute peer storm SPEC --exact`
values the trust-free baseline route's policy in Storm's exact engine instead: the rational beside
our certified value of the route (docs/peers.md, "Storm's exact engine: the value of a fixed
policy"). Needs the optional `[peer]` extra.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import click
from click.core import ParameterSource

from trustroute.app.peers import (
    DEFAULT_MAX_NODES,
    DEFAULT_MAX_STATES,
    DEFAULT_OUR_TIME_LIMIT,
    LIMITS,
    ComparedProblem,
    paynt_comparison,
    storm_comparison,
    storm_exact_comparison,
)
from trustroute.core import ranges
from trustroute.core.errors import InputError
from trustroute.core.wording import counted, interval, lower_text
from trustroute.harness.commands.inputs import driver_field, spec_argument, town_field
from trustroute.harness.commands.option_groups import option, takes
from trustroute.harness.commands.options import Checked
from trustroute.harness.commands.output import emit, json_flag


@dataclass(frozen=True)
class PeerProblem:
    """--town, --driver and --horizon: the problem (with SPEC) both a peer and ours are given."""

    town_path: str | None = town_field()
    driver_path: str | None = driver_field()
    horizon: int | None = option(
        "--horizon", type=Checked(ranges.HORIZON), default=None,
        help="Accepted within H junctions (a step counter in the product; default: unbounded).")

    def compared(self, spec_path: str) -> ComparedProblem:
        """The problem both sides are given."""
        return ComparedProblem(spec_path, self.town_path, self.driver_path, self.horizon)


@dataclass(frozen=True)
class OurSide:
    """--depth, --max-nodes, --our-time-limit and --json: our side of a comparison, and the output."""

    depth: int = option("--depth", type=Checked(ranges.DEPTH), default=10, show_default=True,
                        help="Our search depth for the unbounded objective (the horizon when given).")
    max_nodes: int = option(
        "--max-nodes", type=Checked(ranges.PEER_MAX_NODES), default=DEFAULT_MAX_NODES, show_default=True,
        help="Our belief nodes per level; beyond, the least likely are bounded, not expanded.")
    our_time_limit: float | None = option(
        "--our-time-limit", type=Checked(ranges.OUR_TIME_LIMIT), default=DEFAULT_OUR_TIME_LIMIT,
        help="Seconds of our search; past them it stops with sound bounds, wider than its own end's, "
             "and says so (stopped_by). Default: none: it runs to its end, so its bounds do not "
             "depend on the machine or its load; give one for a long --horizon.")
    as_json: bool = json_flag()


def peer_time_limit(help: str) -> Any:
    return option("--time-limit", type=Checked(ranges.PEER_TIME_LIMIT), default=30.0, show_default=True,
                  help=help)


@dataclass(frozen=True)
class StormLimits:
    """Storm's side: the seconds of its belief unfolding and its discretisation's resolution."""

    time_limit: float = peer_time_limit("Seconds of Storm's belief unfolding (lower bound).")
    resolution: int = option("--resolution", type=Checked(ranges.RESOLUTION), default=2, show_default=True,
                             help="Storm's discretisation resolution (upper bound).")
    exact: bool = option(
        "--exact", is_flag=True,
        help="Instead of the bounds: the trust-free baseline route's value in Storm's exact engine, a "
             "rational, beside our certified value of the route (--horizon defaults to the route's "
             "junctions; --time-limit, --resolution, --depth, --max-nodes and --our-time-limit are "
             "refused).")


@dataclass(frozen=True)
class PayntLimits:
    """PAYNT's side: the seconds of its controller search and the largest product it is handed."""

    time_limit: float = peer_time_limit("Seconds of PAYNT's controller search.")
    max_states: int = option("--max-states", type=Checked(ranges.MAX_STATES), default=DEFAULT_MAX_STATES,
                             show_default=True, help="Largest product POMDP handed to PAYNT; beyond, exit 2.")


def problem_line(result: dict) -> str:
    """A comparison's first line of text: the spec, its objective and the product's size."""
    horizon = result["horizon"]
    objective = f"within {horizon} junctions" if horizon is not None else "unbounded"
    return f"{result['spec']} ({objective}), product POMDP with {result['product_states']} states"


def ours_line(ours: dict) -> str:
    """Our bounds, gap and seconds, as one line of a comparison's text, and the limit that stopped
    our search, if one did."""
    stopped = ours.get("stopped_by")
    return (f"  ours   {interval(ours['lower'], ours['upper'])}  gap {ours['gap']:.2e}  "
            f"{ours['seconds']:.1f} s" + (f", stopped by its {stopped}" if stopped in LIMITS else ""))


@click.group("peer")
def peer() -> None:
    """Independent solvers beside ours."""


@peer.command("storm")
@spec_argument()
@takes(problem=PeerProblem, limits=StormLimits, ours=OurSide)
def storm(spec_path: str, problem: PeerProblem, limits: StormLimits, ours: OurSide) -> None:
    """Storm's [lower, upper] and time beside ours, for SPEC (--exact: a route's exact value)."""
    if limits.exact:
        refuse_unused_with_exact()
        found = storm_exact_comparison(problem.compared(spec_path), progress=not ours.as_json)
        emit(ours.as_json, found, [] if ours.as_json else storm_exact_lines(found))
        return
    result = storm_comparison(problem.compared(spec_path), limits.time_limit, limits.resolution, ours.depth,
                              ours.max_nodes, progress=not ours.as_json, our_time_limit=ours.our_time_limit)
    emit(ours.as_json, result, [] if ours.as_json else storm_lines(result))


# The options a fixed policy's exact value does not use: given with --exact, each is refused.
NOT_WITH_EXACT = {"time_limit": "--time-limit", "resolution": "--resolution", "depth": "--depth",
                  "max_nodes": "--max-nodes", "our_time_limit": "--our-time-limit"}


def refuse_unused_with_exact() -> None:
    """One line, exit 2, for an option of the bounds given with --exact, which would not use it."""
    context = click.get_current_context()
    given = [flag for name, flag in NOT_WITH_EXACT.items()
             if context.get_parameter_source(name) not in (None, ParameterSource.DEFAULT)]
    if given:
        raise InputError("--exact", "", f"{', '.join(given)} {'is' if len(given) == 1 else 'are'} not "
                         "used by the exact value of a fixed route",
                         "drop it, or drop --exact for Storm's bounds beside ours")


# A rational longer than this is told by its size: the packaged model's rows divided by their
# sums give numerators and denominators of hundreds of digits, which --json gives whole.
RATIONAL_SHOWN = 80


def rational_text(value: str) -> str:
    """An exact value "p/q" as text: whole when short, else the digits of p and q."""
    if len(value) <= RATIONAL_SHOWN:
        return value
    numerator, denominator = value.split("/")
    return f"a rational of {len(numerator)} / {len(denominator)} digits (whole in --json)"


def storm_exact_lines(result: dict) -> list[str]:
    """Storm's exact value of the baseline route as text: the rational beside our certified value."""
    exact = result["storm_exact"]
    return [problem_line(result),
            f"  route  {' '.join(result['route'])} ({counted(len(result['route']) - 1, 'junction')}), "
            f"a chain of {result['chain_states']:,} states",
            f"  storm  exact {exact['float']:.12f} (to 12 decimals) = {rational_text(exact['value'])}",
            ours_line(result["ours"]),
            f"  within ours: {'yes' if result['within_ours'] else 'NO'}"]


def storm_lines(result: dict) -> list[str]:
    """Storm's comparison as text."""
    s = result["storm"]
    lines = [problem_line(result),
             f"  storm  {interval(s['lower'], s['upper'])}  gap {s['gap']:.2e}  "
             f"{s['build_seconds'] + s['lower_seconds'] + s['upper_seconds']:.1f} s",
             ours_line(result["ours"]),
             f"  overlap: {'yes' if result['overlap'] else 'NO'}"]
    return lines + note_lines(s)


def note_lines(side: dict) -> list[str]:
    """A peer's note (why it was not run), as a line of a comparison's text."""
    return [f"  note: {side['note']}"] if side.get("note") else []


@peer.command("paynt")
@spec_argument()
@takes(problem=PeerProblem, limits=PayntLimits, ours=OurSide)
def paynt(spec_path: str, problem: PeerProblem, limits: PayntLimits, ours: OurSide) -> None:
    """PAYNT's finite-state controller value (a lower bound of Pr_max) beside ours, for SPEC."""
    result = paynt_comparison(problem.compared(spec_path), limits.time_limit, limits.max_states, ours.depth,
                              ours.max_nodes, progress=not ours.as_json, our_time_limit=ours.our_time_limit)
    emit(ours.as_json, result, [] if ours.as_json else paynt_lines(result))


def paynt_lines(result: dict) -> list[str]:
    """PAYNT's comparison as text."""
    p = result["paynt"]
    # a lower bound of Pr_max, set beside our L: rounded down as ours is
    found = lower_text(p["value"]) if p["found"] else "no controller found in time (lower bound 0)"
    searched = ("not run (note below)" if p.get("note") else
                f"{p['seconds']:.1f} s, controllers up to {p['memory_nodes']} memory nodes per observation")
    return [problem_line(result),
            f"  paynt  {found}  {searched}",
            ours_line(result["ours"]),
            "  PAYNT's value is a LOWER bound of Pr_max: the value of one finite-state controller. "
            "A controller with k memory nodes may be worth less than the best history-dependent "
            "policy, so compare it with our L, not U.",
            f"  within our U: {'yes' if result['within_ours'] else 'NO'}"] + note_lines(p)
