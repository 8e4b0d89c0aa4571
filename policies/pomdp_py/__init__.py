"""trustroute.policies.pomdp_py: the bridge to pomdp-py (an adapter of the trust POMDP and POUCT)."""
