"""trustroute.policies.model: the trust POMDP (with its one Bayes filter) and its product with a DFA."""
