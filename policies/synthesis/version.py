"""The version of the synthesis code, part of every cached policy's key.

Bump SYNTHESIS_VERSION whenever a change to synthesis (policies/synthesis/, the trust POMDP and
belief filter it plans on, the spec compilation, or the "aware" settings in
policies/resolve.py) can change a synthesized policy or its bounds: cached policies made
by older code are then no longer found and are synthesized again.
"""

SYNTHESIS_VERSION = "8"

# The same for the synthesis of specs with trust-state atoms (policies/trust_state_synthesis/,
# policies/evaluation/trust_state.py's evaluate_joint_table, policies/belief/trust_state_filter.py and
# trust_state_relaxation.py, policies/routing/trust_state_table.py): part of the key of those specs'
# cached policies only, so a change
# there rebuilds them and leaves every other cached policy valid.
JOINT_SYNTHESIS_VERSION = "3"
