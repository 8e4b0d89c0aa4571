"""trustroute.policies.synthesis: policies with certified bounds L <= Pr_max <= U.

search (the best-first search that returns the policy and L), belief_cells (the suffix cells that
over-approximate reachable beliefs), upper_bound (where U is computed), exact_search (the exhaustive
optimum used to test the others).
"""
