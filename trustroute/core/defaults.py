"""The defaults every door reads, defined once: the API's keyword defaults, the CLI's option
defaults, the gymnasium environment's settings and the modules that own each rule (the fallback,
the episode cap, the "aware" horizon) are these names, so no door can drift from another
(tests/app/test_defaults.py runs them through the API and the CLI and compares).

Kept free of imports, so the API can name them in its signatures while `import trustroute` stays
cheap.
"""

from __future__ import annotations

from typing import Final

# synthesis (`synthesize`, `trustroute synth`)
TAU = 1e-3                           # target gap upper - lower
TIME_LIMIT = 60.0                    # seconds for the whole synthesis
MAX_TIME_LIMIT = 7 * 24 * 3600.0     # the longest time limit any door takes (a week), in seconds
WORK_LIMIT: int | None = None        # units of work for the whole synthesis (policies/work_clock.py)
# nodes a belief-MDP search may hold (about 1 kB each): past them it stops, whatever its limits
NODE_BUDGET = 600_000
SYNTH_HORIZON: int | None = None     # junctions; None: unbounded
OBJECTIVE: Final = "bayes"            # of a population synthesis ("robust": the worst type's)
BELIEF_RULE: Final = "bayes"            # the AV's filter ("paper": the authors' update)

# episodes and exact evaluation (`evaluate`, `run_episode`, `trustroute evaluate`, `trustroute run`)
POLICY = "free"
FALLBACK_AFTER = 20                  # the study's rule: the shortest completion after this many junctions
JUNCTION_CAP = 60                    # an episode still running after this many junctions ends ("cap")
AWARE_HORIZON = FALLBACK_AFTER       # "aware" is synthesized for the junctions before the fallback
SEED = 0
MAX_SEED = 2**31 - 1                 # the largest episode seed a door takes: SUMO's is a signed 32-bit int
EPISODE_ENGINE = "sumo"
# background vehicles (`run --background`, study key `background_vehicles`, SumoConfig): the most
# any door takes. Not a count every town and seed can carry: a town's traffic can lock itself up
# with fewer (Town01 with 100 on two seeds of ten), which ends the episode with a TrafficJam
# (harness/simulation/background.py).
MAX_BACKGROUND_VEHICLES = 200
# the gymnasium environment's own (docs/gym_env.md): the model engine, fast and without SUMO, for
# the many episodes an agent learns from
GYM_ENGINE = "model"

# analysis (`analyze`, `trustroute analyze`): None lets the analysis choose the study's own default
# belief source (analysis/belief_sources.py, `default_belief_source`), the one definition both
# doors read.
BELIEF_SOURCE: str | None = None

# planning (`trustroute plan`, trustroute/app/planning.py)
PLAN_PARTICIPANTS = "8:60:4"         # the sample sizes tried: FROM:TO:STEP
PLAN_ALPHA = 0.05
PLAN_TARGET = 0.8                    # the power a sample size must reach
PLAN_SEED = 1
# `--pilot`: bootstrap refits of the pilot's fit, one drawn per simulated study (an EM refit of an
# 8-participant pilot takes seconds, a counts refit a few hundredths)
PILOT_BOOTSTRAP = 50
