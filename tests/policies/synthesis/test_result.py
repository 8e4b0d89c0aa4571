"""Typed run statistics: to_dict gives the JSON `trustroute synth --json` prints under "stats"."""

from __future__ import annotations

import json
from dataclasses import replace

from trustroute.policies.synthesis.result import (
    ClusterAttempt,
    ClusterRun,
    GraphDistanceRun,
    SearchRun,
    SynthesisStats,
)

SEARCH_KEYS = ["horizon", "suffix_length", "abstract_cells", "abstraction_seconds",
               "abstraction_clock_seconds", "abstraction_bound",
               "abstraction_root_upper", "root_dfa_states", "lower_strict_labels",
               "completion_closed", "completion_bounds", "free_tree_leaves", "completion_seconds",
               "completion_clusters", "compressed", "macro_width", "row_conflicts", "nodes",
               "expanded_nodes", "open_frontier_nodes", "open_frontier_mass_upper_policy", "iterations",
               "stopped", "policy_rows", "lower", "upper"]


def _search_run(**changes) -> SearchRun:
    run = SearchRun(horizon=None, suffix_length=2, abstract_cells=7, abstraction_seconds=0.1,
                    abstraction_clock_seconds=0.1,
                    abstraction_bound="b", abstraction_root_upper=1.0, root_dfa_states=(0, 2),
                    lower_strict_labels=0.4, completion_closed=True,
                    completion_bounds=False, free_tree_leaves=4.0, completion_seconds=0.0,
                    completion_clusters=0, compressed=None, macro_width=None, row_conflicts=0, nodes=9,
                    expanded_nodes=2, open_frontier_nodes=1, open_frontier_mass_upper_policy=0.5,
                    iterations=1, stopped="deadline", policy_rows=2, lower=0.5, upper=0.9)
    return replace(run, **changes)


def test_search_run_keys_in_order_with_the_end_component_time_only_when_set():
    plain = _search_run().to_dict()
    assert list(plain) == SEARCH_KEYS
    assert plain["root_dfa_states"] == [0, 2]
    assert plain["compressed"] is None and plain["macro_width"] is None      # kept when None
    unbounded = _search_run(end_component_seconds=1.5).to_dict()
    assert list(unbounded) == [*SEARCH_KEYS, "end_component_seconds"]


def test_cluster_and_graph_distance_runs():
    tried = (ClusterAttempt(cap=16, lower=0.2, upper=0.8, clusters=5, rows=4, seconds=0.1),
             ClusterAttempt(cap=64))
    run = ClusterRun(horizon=12, lower=0.2, upper=0.8, cluster_cap=16, clusters=5, policy_rows=4,
                     cluster_runs=tried, lower_strict_labels=0.2).to_dict()
    assert list(run) == ["horizon", "method", "lower", "upper", "nodes", "cluster_cap", "clusters",
                         "policy_rows", "cluster_runs", "lower_strict_labels",
                         "completion_closed", "completion_bounds"]
    assert run["method"] == "cluster policy" and run["nodes"] == 0 and run["completion_closed"]
    assert run["cluster_runs"] == [{"cap": 16, "lower": 0.2, "upper": 0.8, "clusters": 5, "rows": 4,
                                    "seconds": 0.1}, {"cap": 64, "stopped": "deadline"}]
    distance = GraphDistanceRun(horizon=3, abstraction_bound="graph distance", root_dfa_states=(1,))
    assert list(distance.to_dict()) == ["horizon", "lower", "upper", "nodes", "abstraction_root_upper",
                                        "abstraction_bound", "lower_strict_labels", "root_dfa_states",
                                        "completion_closed", "completion_bounds"]


def test_synthesis_stats_keys_for_bounded_unbounded_and_robust():
    runs = (_search_run(horizon=20), _search_run())
    bounded = SynthesisStats(belief_rule="bayes", converged=True, tau=1e-3, runs=runs[:1],
                             policy_rows=2, lower_strict_labels=0.5)
    head = ["method", "belief_rule", "converged", "tau", "runs", "policy_rows", "lower_strict_labels"]
    assert list(bounded.to_dict()) == head
    # unbounded: lower_from_horizon is kept when None (the unbounded search's run has no horizon)
    unbounded = replace(bounded, runs=runs, unbounded_upper="note", lower_from_horizon=None)
    assert list(unbounded.to_dict()) == [*head, "unbounded_upper", "lower_from_horizon"]
    assert unbounded.to_dict()["lower_from_horizon"] is None
    robust = replace(unbounded, objective="robust").to_dict()
    assert list(robust) == [*head, "unbounded_upper", "lower_from_horizon", "objective"]
    assert list(replace(bounded, objective="robust").to_dict()) == [*head, "objective"]
    assert json.loads(json.dumps(robust)) == robust           # plain JSON data throughout
