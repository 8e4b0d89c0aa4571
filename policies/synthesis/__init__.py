"""trustroute.policies.synthesis: policies with certified bounds L <= Pr_max <= U.

belief_synthesis (`synthesize`, the entry point: its phases and their time shares), belief_graph
(the search's node store), expansion (expansion, backups, reach), open_node_bounds (how open nodes
are valued, the hold rule), refinement (the anytime rounds of one search), policy_extraction (the
policy's table rows), belief_cells (the suffix cells that over-approximate reachable beliefs),
upper_bound (where U is computed), end_components (the unbounded bound), cluster_policy and
completion_value (box clusters), population (driver populations), budget (the time-budget
scheduler), result (SynthesisResult and typed statistics), exact_search (the exhaustive optimum
used to test the others).
"""
