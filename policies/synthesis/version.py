"""The version of the synthesis code, part of every cached policy's key.

Bump SYNTHESIS_VERSION whenever a change to synthesis (policies/synthesis/, the trust POMDP and
belief filter it plans on, the spec compilation, or the "aware" settings in
policies/routing/resolve.py) can change a synthesized policy or its bounds: cached policies made
by older code are then no longer found and are synthesized again.
"""

SYNTHESIS_VERSION = "3"
