"""trustroute.policies.pomdp_py: the bridge to pomdp-py (POUCT on the trust POMDP × spec DFA, a baseline)."""
