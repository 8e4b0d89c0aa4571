"""policies: deciding routes.

Owns the trust POMDP, the Bayes belief filter, the scLDTL language and its DFA,
the product belief MDP, synthesis with certified bounds, policy files, the
trust-free baseline and the POUCT baseline on pomdp-py. Must not know about SUMO.
"""
