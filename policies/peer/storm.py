"""Storm's POMDP belief exploration on the exported product (stormpy, the optional `[peer]` extra).

Two sound one-sided results for Pmax=? [F "goal"]: belief-MDP unfolding gives a lower bound
(the value of a policy Storm found, cut off at a time or size limit), belief discretisation
(Freudenthal triangulation at a resolution) an upper bound. With a step counter in the model
both are for the bounded objective. Storm computes in double precision with its default
(iterative, ε = 1e-6 relative) solvers, so its numbers are sound up to that solver precision,
not certified in our sense; they are an independent check, reported as Storm gives them.

`storm_exact_value` is Storm's exact engine (rationals, no solver tolerance) on the chain a fixed
policy makes of the product (`induced_chain`): the policy's value as a rational.

A product in which no reachable state satisfies the spec (no satisfying route fits the horizon)
has the value 0 exactly; Storm rejects a property whose label no state carries, so it is not run
and the result says why (`note`). Any other error Storm raises on a product is an InputError.
"""

from __future__ import annotations

import importlib.util
import tempfile
import time
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from trustroute.core.errors import InputError
from trustroute.policies.bracket import Bracket
from trustroute.policies.peer.product_pomdp import ExplicitProduct, no_goal_note

INSTALL_HINT = "install the optional peer extra: pip install 'trustroute[peer]' (stormpy==2.0.0)"


def storm_available() -> bool:
    return importlib.util.find_spec("stormpy") is not None


def require_storm(source: str = "stormpy") -> None:
    """InputError with the install hint when stormpy is absent."""
    if not storm_available():
        raise InputError(source, "", "Storm (stormpy) is not installed", INSTALL_HINT)


@dataclass(frozen=True)
class StormResult(Bracket):
    lower: float
    upper: float
    lower_seconds: float
    upper_seconds: float
    build_seconds: float
    lower_complete: bool
    upper_complete: bool
    states: int
    choices: int
    observations: int
    lower_beliefs: int
    upper_beliefs: int
    resolution: int
    time_limit: float
    note: str = ""   # why Storm was not run, when the answer needs no solver
    max_beliefs: int | None = None   # the unfolding's limit on discovered beliefs, if any


NO_GOAL_NOTE = no_goal_note("Storm")


def build_storm_model(product: ExplicitProduct, exact: bool = False) -> tuple[Any, Any, float]:
    """(POMDP, property, build seconds): the product written as DRN and read by Storm (stormpy's
    objects carry no type information); `exact`: its probabilities as rationals, read into a model
    over Storm's exact rationals."""
    require_storm()
    import stormpy
    from stormpy.io import DirectEncodingParserOptions

    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="trustroute-storm-") as folder:
        path = Path(folder) / "product.drn"
        path.write_text(product.to_drn(exact=exact))
        options = DirectEncodingParserOptions()
        options.build_choice_labeling = True     # Storm's POMDP checks match actions by label
        build = stormpy.build_model_from_drn[stormpy.Rational] if exact else stormpy.build_model_from_drn
        model = build(str(path), options=options)
    properties = stormpy.parse_properties(product.query)
    return model, properties[0], time.perf_counter() - started


def storm_exact_value(chain: ExplicitProduct) -> Fraction:
    """P(F goal) from `begin` in a product with one choice per state (`induced_chain`: the value
    of a fixed policy), by Storm's exact engine: the model over rationals, its exact environment
    (no iterative solver, no tolerance). 0 without Storm when no state of the chain is a goal."""
    if not chain.goal.any():
        return Fraction(0)
    if int(np.bincount(chain.choice_state, minlength=chain.n_states).max()) > 1:
        raise ValueError("Storm's exact value of a policy needs one choice per state (induced_chain)")
    # Storm's exact DRN reader takes a row that is not a distribution as it is (a row summing to
    # 1 + 1e-12 moves the value without a word), so the rows are checked here, exactly.
    totals = [Fraction(0)] * chain.choice_state.size
    factors = chain.rationals()
    for choice, code in zip(chain.transition_choice.tolist(), chain.transition_factor.tolist(), strict=True):
        totals[choice] += factors[code]
    if any(total != 1 for total in totals):
        raise ValueError("a choice's exact probabilities do not sum to 1")
    model, prop, _ = _storm_call(build_storm_model, chain, exact=True)
    import stormpy

    result = _storm_call(stormpy.model_checking, model, prop, only_initial_states=True,
                         force_fully_observable=True, environment=stormpy.environments.exact())
    return Fraction(str(result.get_value(0)))


def _unreachable_goal(product: ExplicitProduct, time_limit: float, resolution: int) -> StormResult:
    choices = int(product.choice_state.size)
    observations = int(product.observation.max()) + 1 if product.n_states else 0
    return StormResult(
        lower=0.0, upper=0.0, lower_seconds=0.0, upper_seconds=0.0, build_seconds=0.0,
        lower_complete=True, upper_complete=True, states=product.n_states, choices=choices,
        observations=observations, lower_beliefs=0, upper_beliefs=0, resolution=resolution,
        time_limit=float(time_limit), note=NO_GOAL_NOTE)


def _storm_call(call: Any, *args: Any, **kwargs: Any) -> Any:
    """Storm's answer, or an InputError with the first line of Storm's complaint."""
    try:
        return call(*args, **kwargs)
    except RuntimeError as exc:
        complaint = (str(exc).strip().splitlines() or ["(no message)"])[0]
        raise InputError("trustroute peer storm", "", f"Storm cannot take this product: {complaint}",
                         "check the spec, town and driver model; "
                         "run `trustroute synth` for our bounds alone") from exc


def run_storm(product: ExplicitProduct, time_limit: float = 10.0, resolution: int = 2,
              max_beliefs: int | None = None) -> StormResult:
    """Storm's lower (unfolding, at most `time_limit` seconds of exploration and, given, at most
    `max_beliefs` discovered beliefs) and upper (discretisation at `resolution`, which Storm cannot
    stop early) bounds; [0, 0] with a note, without Storm, when no reachable state satisfies the
    spec. Storm checks its clock seldom and can run past `time_limit` (2.8 s at a limit of 1 s on a
    small town); `max_beliefs` stops it at the same point on any machine."""
    if not product.goal.any():
        return _unreachable_goal(product, max(1, int(round(time_limit))), resolution)
    model, prop, build_seconds = _storm_call(build_storm_model, product)
    import stormpy.pomdp as storm_pomdp

    seconds = max(1, int(round(time_limit)))
    started = time.perf_counter()
    lower = _storm_call(storm_pomdp.verify_with_belief_unfolding, model, prop,
                        max_exploration_time=seconds, max_exploration_size=max_beliefs)
    lower_seconds = time.perf_counter() - started

    # Storm's discretisation takes no time or size limit: its cost is set by the resolution.
    started = time.perf_counter()
    upper = _storm_call(storm_pomdp.verify_with_belief_discretization, model, prop, resolution=resolution)
    upper_seconds = time.perf_counter() - started
    return StormResult(
        lower=float(lower.value), upper=float(upper.value), lower_seconds=lower_seconds,
        upper_seconds=upper_seconds, build_seconds=build_seconds,
        lower_complete=bool(lower.completed_exploration),
        upper_complete=bool(upper.completed_exploration), states=int(model.nr_states),
        choices=int(model.nr_choices), observations=int(model.nr_observations),
        lower_beliefs=int(lower.statistics.explored_beliefs or 0),
        upper_beliefs=int(upper.statistics.explored_beliefs or 0), resolution=resolution,
        time_limit=float(seconds), max_beliefs=max_beliefs)
