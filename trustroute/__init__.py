"""trustroute: a study harness on SUMO for trust-aware routing of an autonomous vehicle.

Subpackages: networks (towns and SUMO nets), participants (driver models), policies (scLDTL,
the trust POMDP, synthesis, routing policies), harness (episodes, studies, the CLI), analysis
(satisfaction, statistics, reports, fitting).
"""
