"""trustroute.policies.routing: routing policies and their files.

protocol (the RoutingPolicy interface), free (trust-free shortest routes), aware_table (the
synthesized belief-table policy), fallback (the 20-junction rule), files (policy files), resolve
("aware" / "free" / a file -> a policy, with the policy cache).
"""
