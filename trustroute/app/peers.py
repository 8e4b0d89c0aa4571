"""The independent peers beside ours on one problem (docs/peers.md): the problem loaded as every
command loads it, exported as the explicit product a peer is given, and both sides' bounds;
`trustroute peer storm` and `trustroute peer paynt` print them. The peers themselves are the
optional `[peer]` extra, imported only when a comparison runs. `trustroute peer storm --exact`
values one fixed policy instead, the trust-free baseline route's, in Storm's exact engine: its
rational beside our certified value of the same route (`trustroute baseline`). Each step after loading (the
export, the peer, ours) reports nothing while it runs, so with `progress` a line on stderr names the
step under way every few seconds once they have run 2 s (`step_progress`); the inputs are loaded and
checked before, so that bad input stays one line."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from trustroute.app.inputs import load_inputs
from trustroute.app.problem import compile_problem
from trustroute.app.synthesis import baseline
from trustroute.core.errors import InputError
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.peer.paynt import MAX_PRODUCT_STATES, require_paynt, run_paynt
from trustroute.policies.peer.product_pomdp import (
    ExplicitProduct,
    check_exportable,
    explicit_product,
    induced_chain,
    route_choices,
)
from trustroute.policies.resolve import step_progress
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.trust_state_synthesis.search import JointBounds, JointLimits, joint_search
from trustroute.policies.work_clock import LIMITS as LIMITS

# The defaults the CLI offers, from the definitions the solvers use.
DEFAULT_MAX_NODES = JointLimits.max_nodes
# Our side's time limit by default: none, so that our search runs to its end and its bounds do
# not depend on the machine or its load; given, the search stops by it with sound, wider bounds
# and says so ("stopped_by" one of LIMITS).
DEFAULT_OUR_TIME_LIMIT: float | None = None
DEFAULT_MAX_STATES = MAX_PRODUCT_STATES


@dataclass(frozen=True)
class ComparedProblem:
    """The problem both a peer and ours are given: SPEC, --town, --driver and --horizon (None:
    unbounded)."""

    spec_path: str
    town_path: str | None = None
    driver_path: str | None = None
    horizon: int | None = None


def exportable_inputs(problem: ComparedProblem):
    """The problem's inputs, its spec one a peer can state (else InputError)."""
    inputs = load_inputs(problem.spec_path, problem.town_path, problem.driver_path)
    check_exportable(inputs.spec)
    return inputs


def loaded_problem(problem: ComparedProblem) -> tuple:
    """(spec, our POMDP) for one comparison, the spec one a peer can state."""
    inputs = exportable_inputs(problem)
    return inputs.spec, build_pomdp(inputs.town, inputs.model)


def our_bounds(pomdp, spec, horizon: int | None, depth: int, max_nodes: int,
               time_limit: float | None = DEFAULT_OUR_TIME_LIMIT) -> JointBounds:
    """Our side of a comparison: the trust-state search's bounds on the same problem, within
    `time_limit` seconds when given (a deadline on the synthesis clock, as a synthesis' time limit
    is: policies/work_clock.py; past it the search stops with sound bounds, `stopped_by` naming the
    limit), else to the search's end."""
    deadline = None if time_limit is None else TimeBudget.start(time_limit).deadline
    limits = JointLimits(max_nodes=max_nodes, deadline=deadline)
    return joint_search(pomdp, spec, depth, horizon, limits=limits)[0]


def _both_sides(problem: ComparedProblem, peer: str, run_peer: Callable[[ExplicitProduct], Any], depth: int,
                max_nodes: int, progress: bool, our_time_limit: float | None) -> tuple[dict, Any, Any]:
    """(the problem's JSON fields, the peer's result, ours): the product exported, `run_peer` on it
    and our search (within `our_time_limit` seconds, `our_bounds`), each step named by the progress
    lines of `trustroute peer <peer>`."""
    spec, pomdp = loaded_problem(problem)
    with step_progress(f"peer {peer.lower()}", progress) as step:
        step("exporting the product POMDP")
        product = explicit_product(pomdp, spec, problem.horizon)
        step(f"{peer} on {product.n_states:,} product states")
        theirs = run_peer(product)
        step("our search")
        ours = our_bounds(pomdp, spec, problem.horizon, depth, max_nodes, our_time_limit)
    fields = {"spec": spec.name, "file": spec.source_path, "horizon": problem.horizon,
              "product_states": product.n_states}
    return fields, theirs, ours


def storm_comparison(problem: ComparedProblem, time_limit: float, resolution: int, depth: int,
                     max_nodes: int, progress: bool = False,
                     our_time_limit: float | None = DEFAULT_OUR_TIME_LIMIT) -> dict:
    """Both sides' bounds and seconds, JSON-ready (`our_time_limit`: our search's, `our_bounds`)."""
    from trustroute.policies.peer.storm import require_storm, run_storm

    require_storm("trustroute peer storm")
    fields, storm, ours = _both_sides(
        problem, "Storm", lambda product: run_storm(product, time_limit=time_limit, resolution=resolution),
        depth, max_nodes, progress, our_time_limit)
    return {**fields, "storm": storm.to_dict(), "ours": ours.to_dict(),
            "overlap": bool(max(storm.lower, ours.lower) <= min(storm.upper, ours.upper) + 1e-9)}


def paynt_comparison(problem: ComparedProblem, time_limit: float, max_states: int, depth: int,
                     max_nodes: int, progress: bool = False,
                     our_time_limit: float | None = DEFAULT_OUR_TIME_LIMIT) -> dict:
    """PAYNT's controller value beside our bounds, JSON-ready (`our_time_limit`: our search's,
    `our_bounds`)."""
    require_paynt("trustroute peer paynt")
    fields, paynt, ours = _both_sides(
        problem, "PAYNT", lambda product: run_paynt(product, time_limit=time_limit, max_states=max_states),
        depth, max_nodes, progress, our_time_limit)
    return {**fields, "paynt": paynt.to_dict(), "ours": ours.to_dict(),
            "within_ours": bool(paynt.lower <= ours.upper + paynt.precision)}


def exact_horizon(problem: ComparedProblem, source: str, junctions: int) -> int:
    """The step bound of the product an exact run exports for a route of `junctions` junctions:
    --horizon, else the route's own (beyond it the policy has ended the episode, so a longer one
    gives the same value); an InputError for a --horizon that would cut the route short."""
    if problem.horizon is None:
        return max(junctions, 1)   # a spec decided on its start road: at least one junction, as --horizon
    if problem.horizon < junctions:
        raise InputError(source, "--horizon", f"the baseline route drives {junctions} junctions, more "
                         f"than --horizon {problem.horizon}: Storm would value the route cut short",
                         f"pass --horizon {junctions} or more, or leave it out for the route's own")
    return problem.horizon


def storm_exact_comparison(problem: ComparedProblem, progress: bool = False) -> dict:
    """Storm's exact value (a rational) of the policy that drives the trust-free baseline route,
    on the chain that policy makes of the product (`induced_chain`), beside our certified [L, U]
    of the same route (`baseline`), JSON-ready: the rational as its text, "p/q" (or "p")."""
    from trustroute.policies.peer.storm import require_storm, storm_exact_value

    require_storm("trustroute peer storm --exact")
    compiled = compile_problem(exportable_inputs(problem))
    spec, pomdp = compiled.spec, compiled.pomdp
    with step_progress("peer storm", progress) as step:
        step("our evaluation of the baseline route")
        ours = baseline(compiled)
        horizon = exact_horizon(problem, spec.source_path or spec.name, len(ours.route) - 1)
        step("exporting the product POMDP")
        product = explicit_product(pomdp, spec, horizon, exact=True)
        chain = induced_chain(product, route_choices(product, pomdp, ours.route))
        step(f"Storm's exact engine on {chain.n_states:,} chain states")
        value = storm_exact_value(chain)
    lower, upper = ours.value.lower, ours.value.upper
    return {"spec": spec.name, "file": spec.source_path, "horizon": horizon,
            "product_states": product.n_states, "route": ours.route, "chain_states": chain.n_states,
            "storm_exact": {"value": str(value), "float": float(value)},
            "ours": {"lower": lower, "upper": upper, "gap": upper - lower, "seconds": ours.value.seconds},
            "within_ours": bool(Fraction(lower) <= value <= Fraction(upper))}
