"""How a synthesis searches: one frozen settings object, checked once where it is made and passed
down from the entry points (policies/synthesize_spec.py, policies/synthesis/belief_synthesis.py,
the population syntheses) to the search itself (refinement.py, expansion.py)."""

from __future__ import annotations

from dataclasses import dataclass

from trustroute.core import defaults
from trustroute.policies.model.trust_pomdp import BeliefRule
from trustroute.policies.synthesis.arguments import check_synthesis_arguments

DEFAULT_BATCH = 4096
# How open nodes are valued (expansion.py): "exact" trees along the free moves, "bounds" (cluster
# bounds on the completion), "auto": exact where the trust-free route's observation tree is small.
COMPLETION_MODES = ("auto", "exact", "bounds")
COMPRESS_MODES = ("off", "chains", "full")
# Cluster policies (cluster_policy.py): "auto" before or after the search (belief_synthesis.py),
# "early" where "auto" puts them before the search and never after it (the population syntheses:
# after the lifted search they took half of its time and never beat its L), "on" always before
# the search, "off" never.
CLUSTER_MODES = ("auto", "early", "on", "off")


def _check_choice(what: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"unknown {what} {value!r}; use one of {', '.join(choices)}")


@dataclass(frozen=True)
class SynthesisSettings:
    """tau: stop when upper - lower <= tau at the root. time_limit: seconds for the whole call.
    horizon: at most this many junctions (None: unbounded). belief_rule: the AV's filter ("bayes"
    or the authors' "paper" update). suffix_length: the abstraction's (None: chosen from the
    problem). work_limit: units of work for the whole call (policies/work_clock.py: a deterministic
    stop, the same on any machine; None: the time limit alone). node_budget: the most nodes a
    search holds (it stops there, whatever its limits). batch: nodes expanded per round.
    compress, completion, clusters: the search's modes
    (COMPRESS_MODES, COMPLETION_MODES, CLUSTER_MODES; docs/synthesis.md). grid_points: candidate
    type priors of a population's robust objective (None: policies/synthesis/population.py's)."""

    tau: float = 1e-3
    time_limit: float = 60.0
    horizon: int | None = None
    belief_rule: BeliefRule = "bayes"
    suffix_length: int | None = None
    batch: int = DEFAULT_BATCH
    compress: str = "chains"
    completion: str = "auto"
    clusters: str = "auto"
    grid_points: int | None = None
    work_limit: int | None = None
    node_budget: int = defaults.NODE_BUDGET

    def __post_init__(self) -> None:
        check_synthesis_arguments(self.tau, self.horizon, self.belief_rule)
        if self.work_limit is not None and not (isinstance(self.work_limit, int) and self.work_limit >= 1):
            raise ValueError(f"work_limit must be a positive number of units, got {self.work_limit!r}")
        if not (isinstance(self.node_budget, int) and self.node_budget >= 1):
            raise ValueError(f"node_budget must be a positive number of nodes, got {self.node_budget!r}")
        _check_choice("completion", self.completion, COMPLETION_MODES)
        _check_choice("clusters", self.clusters, CLUSTER_MODES)
        if self.compress not in COMPRESS_MODES:
            raise ValueError(f"unknown compression {self.compress!r}; use one of {', '.join(COMPRESS_MODES)}")


DEFAULT_SYNTHESIS = SynthesisSettings()
