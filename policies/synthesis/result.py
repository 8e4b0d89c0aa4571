"""What a synthesis returns: the policy with certified lower <= Pr_max <= upper (SynthesisResult),
and typed statistics of how the bounds were obtained.

The belief-MDP synthesis (belief_synthesis.py) reports SynthesisStats with one record per run:
a search (SearchRun), a cluster policy (ClusterRun) or an answer by graph distance alone
(GraphDistanceRun). `to_dict()` gives the JSON that `trustroute synth --json` prints under "stats".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any, Generic, Protocol, TypeAlias, TypeVar

from trustroute.policies.routing.decision_tables import fallback_only
from trustroute.policies.routing.protocol import RoutingPolicy

PolicyT = TypeVar("PolicyT")


# A synthesis' progress after each round: (L, U), the bounds its result will show so far; L is None
# while it has none yet (a synthesis whose L is a valued policy's, before the first is valued; a
# robust population synthesis before its Bayes policy's worst type is valued).
RoundProgress: TypeAlias = Callable[[float | None, float], None]


def robust_progress(on_iteration: RoundProgress | None, lower: Callable[[], float | None], upper: float,
                    own_upper: bool) -> RoundProgress | None:
    """The progress a synthesis run inside a robust population synthesis tells: the robust result's
    bounds so far, not the run's own (the Bayes objective's or a candidate prior's, another
    probability). `lower()`: the best candidate's worst type (None before one is valued); `upper`:
    the robust bound known so far, narrowed by the run's own U when `own_upper` (the Bayes run,
    whose U the robust bound takes)."""
    if on_iteration is None:
        return None
    told = on_iteration

    def on_round(_lower: float | None, run_upper: float) -> None:
        told(lower(), min(upper, run_upper) if own_upper else upper)

    return on_round


class Statistics(Protocol):
    """What every synthesis' statistics have: convergence, what ended the synthesis where it says
    (a cap of its own, work_clock.CAPS, or an end of its kind; None where it does not say), the
    policy's rows, and their JSON."""

    @property
    def converged(self) -> bool: ...

    @property
    def stopped(self) -> str | None: ...

    @property
    def policy_rows(self) -> int: ...

    def to_dict(self) -> dict: ...


StatsT = TypeVar("StatsT", bound=Statistics)


class Record:
    """A record of how bounds were obtained (a run, an attempt): its JSON is `to_dict()`, and a
    record inside another's fields is written by its own `to_dict`."""

    def to_dict(self) -> dict:
        return record_dict(self)


def _plain(value: Any) -> Any:
    """`value` as JSON-ready data: records by their to_dict, tuples as lists."""
    if isinstance(value, Record):
        return value.to_dict()
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def record_dict(record: Any, optional: tuple[str, ...] = ()) -> dict:
    """A dataclass record's fields in order as a dict; the `optional` ones only when not None."""
    out = {}
    for f in fields(record):
        value = getattr(record, f.name)
        if f.name in optional and value is None:
            continue
        out[f.name] = _plain(value)
    return out


SEARCH_STOPS = ("convergence", "node budget", "deadline", "frontier closed")


@dataclass(frozen=True, kw_only=True)
class SearchRun(Record):
    """One AO*-style search of the product belief MDP (refinement.py): horizon None is the
    unbounded problem (then end_component_seconds: the unbounded abstraction's bound's time)."""

    horizon: int | None
    suffix_length: int
    abstract_cells: int
    abstraction_seconds: float          # wall-clock seconds from the synthesis' start to its search
    # the same fixed costs on the synthesis' clock (policies/work_clock.py: the work done, in the
    # scheduler's seconds, under a work limit; the wall clock without one): what a schedule
    # predicts the next run's fixed costs from (population.py, setup_seconds)
    abstraction_clock_seconds: float
    abstraction_bound: str
    abstraction_root_upper: float
    root_dfa_states: tuple[int, ...]
    # the run's policy's value with labels read as the vehicle reads them (policies/belief/
    # exact_labels.py) from the root the vehicle is in: a lower bound of what `evaluate` measures
    lower_strict_labels: float
    completion_closed: bool
    # open nodes valued by cluster bounds (then L is a lower bound of the policy's value) or
    # by exact trees (then, closed, L is its exact value)
    completion_bounds: bool
    free_tree_leaves: float
    completion_seconds: float
    completion_clusters: int
    # the event graph's macro moves (None: not asked for), their widest context, and contexts
    # where the paths of two rows crossed (then L is a lower bound of the policy's value)
    compressed: bool | None
    macro_width: int | None
    row_conflicts: int
    nodes: int
    expanded_nodes: int
    open_frontier_nodes: int
    open_frontier_mass_upper_policy: float
    iterations: int
    # what ended its refinement (SEARCH_STOPS): "convergence" (the root's gap reached its tau),
    # "node budget", "deadline" (its share of the time or work limit), or "frontier closed" (no
    # open node carries any of the gap: more time would not move its bounds)
    stopped: str
    policy_rows: int
    lower: float
    upper: float
    end_component_seconds: float | None = None

    def to_dict(self) -> dict:
        return record_dict(self, optional=("end_component_seconds",))


@dataclass(frozen=True, kw_only=True)
class ClusterAttempt(Record):
    """One cap tried by best_cluster_solution (cluster_policy.py); lower is None when the
    deadline stopped it."""

    cap: int
    lower: float | None = None
    upper: float | None = None
    clusters: int | None = None
    rows: int | None = None
    seconds: float | None = None

    def to_dict(self) -> dict:
        if self.lower is None:
            return {"cap": self.cap, "stopped": "deadline"}
        return record_dict(self)


@dataclass(frozen=True, kw_only=True)
class ClusterRun(Record):
    """A cluster policy (cluster_policy.py) with the caps tried; labels are read the worse way
    wherever a box straddles a threshold, so L holds under any reading."""

    horizon: int
    method: str = "cluster policy"
    lower: float
    upper: float
    nodes: int = 0
    cluster_cap: int
    clusters: int
    policy_rows: int
    cluster_runs: tuple[ClusterAttempt, ...]
    lower_strict_labels: float
    completion_closed: bool = True
    completion_bounds: bool = False


@dataclass(frozen=True, kw_only=True)
class GraphDistanceRun(Record):
    """An answer without search: no route accepts within the horizon (L = U = 0)."""

    horizon: int | None
    lower: float = 0.0
    upper: float = 0.0
    nodes: int = 0
    abstraction_root_upper: float = 0.0
    abstraction_bound: str
    lower_strict_labels: float = 0.0
    root_dfa_states: tuple[int, ...]
    completion_closed: bool = True
    completion_bounds: bool = False


Run = SearchRun | ClusterRun | GraphDistanceRun


@dataclass(frozen=True, kw_only=True)
class SynthesisStats:
    """How a belief-MDP synthesis obtained its bounds. lower_strict_labels: the returned policy's
    value with labels read as the vehicle reads them (exact where floats cannot decide), a lower
    bound of what `evaluate` measures (a run's lower_strict_labels is that run's policy's).
    Unbounded: unbounded_upper says how U was obtained and lower_from_horizon which run's horizon
    gave L. objective: "robust" for the robust population objective (population.py)."""

    method: str = "AO*-style expansion of the product belief MDP with suffix-abstraction upper bounds"
    belief_rule: str
    converged: bool
    tau: float
    runs: tuple[Run, ...]
    policy_rows: int
    lower_strict_labels: float
    unbounded_upper: str | None = None
    lower_from_horizon: int | None = None
    objective: str | None = None
    # "depth cap": an unbounded synthesis ran every step of its schedule (belief_synthesis.py,
    # UNBOUNDED_HORIZONS and the cluster rounds) unconverged, none cut by its limit
    stopped: str | None = None

    def to_dict(self) -> dict:
        out = record_dict(self, optional=("unbounded_upper", "lower_from_horizon", "objective", "stopped"))
        if self.unbounded_upper is not None:
            # (kept when None: the unbounded search's own run has no horizon)
            out["lower_from_horizon"] = self.lower_from_horizon
        if self.objective is not None:
            out["objective"] = out.pop("objective")          # last, after the unbounded keys
        return out


@dataclass(frozen=True, eq=False)
class SynthesisResult(Generic[PolicyT, StatsT]):
    """lower <= Pr_max <= upper; lower is a certified lower bound of the value of `policy`.

    horizon: the junction horizon solved for (None: unbounded); stats: how the bounds were obtained.
    stopped_by: what ended the call, "convergence", "node budget", one of the caps of the method's
        own (work_clock.CAPS: "cluster cap" and, unbounded, "depth cap" (SynthesisStats.stopped) of
        the belief-MDP synthesis; "node cap", "junction cap",
        "depth cap" or "rounding margin" of the trust-state synthesis, JOINT_STOPS in
        policies/trust_state_synthesis/synthesis.py; "candidate grid" of the robust population
        objective, every candidate prior run and none cut), "work limit" or "time limit"
    (policies/work_clock.py, `stopped_by`; None where the caller did not say).
    """

    policy: PolicyT
    lower: float
    upper: float
    seconds: float
    stats: StatsT
    horizon: int | None = None
    belief_rule: str = "bayes"
    stopped_by: str | None = None

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    @property
    def fallback_only(self) -> str | None:
        """What drives everywhere, in words, when the policy has no synthesized decision and is only
        its table kind's fallback (docs/synthesis.md, "A policy that is only its fallback"); None
        when it has one."""
        return fallback_only(self.policy) if isinstance(self.policy, RoutingPolicy) else None
