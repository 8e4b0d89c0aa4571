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
MAX_HORIZON = 1_000                  # the longest horizon any door takes (a study config's too)
# grid states (x, θ, q, last (h, e), step) of the product POMDP a peer is handed, about 2 kB each
# while it is built: past them the export is refused before it allocates (policies/peer/product_pomdp.py)
MAX_PEER_PRODUCT = 1_000_000
OBJECTIVE: Final = "bayes"            # of a population synthesis ("robust": the worst type's)
BELIEF_RULE: Final = "bayes"            # the AV's filter ("paper": the authors' update)
# cluster policies (docs/synthesis.md): the modes a door takes (the search has one more of its own,
# policies/synthesis/settings.py), and the one it uses unless told
CLUSTER_MODES: Final = ("auto", "on", "off")
CLUSTERS: Final = "auto"

# episodes and exact evaluation (`evaluate`, `run_episode`, `trustroute evaluate`, `trustroute run`)
POLICY = "free"
FALLBACK_AFTER = 20                  # the study's rule: the shortest completion after this many junctions
JUNCTION_CAP = 60                    # an episode still running after this many junctions ends ("cap")
AWARE_HORIZON = FALLBACK_AFTER       # "aware" is synthesized for the junctions before the fallback
MAX_JUNCTIONS = 10_000               # the most junctions a fallback or an episode cap names at any door
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

# studies (`run_study`, `trustroute study`): worker processes, None: the CPU count (at most
# MAX_WORKERS). Every episode's draws are seeded, so the count changes the time a study takes, never
# its data.
WORKERS: int | None = None
MAX_WORKERS = 256
MAX_PARTICIPANTS = 100_000           # of a study, and of every sample size `trustroute plan` simulates
ATTEMPTS = 2                         # runs of a failing episode at most: the first and its retries
MAX_ATTEMPTS = 10

# analysis (`analyze`, `trustroute analyze`): None lets the analysis choose the study's own default
# belief source (analysis/belief_sources.py, `default_belief_source`), the one definition both
# doors read.
BELIEF_SOURCE: str | None = None
# Whether `analyze` (re)writes report.md, report.html and plots/ into the study directory when not
# told (`--report`/`--no-report`, report=): a door that hands the analysis over as data (the API's
# `analyze`, `trustroute analyze --json`) writes no file unless asked; the command printing its
# tables rewrites the report beside them.
REPORT_WITH_DATA = False
REPORT_WITH_TABLES = True

# planning (`trustroute plan`, trustroute/app/planning.py)
PLAN_PARTICIPANTS = "8:60:4"         # the sample sizes tried: FROM:TO:STEP
PLAN_ALPHA = 0.05
PLAN_TARGET = 0.8                    # the power a sample size must reach
PLAN_SEED = 1
# the tests a plan can run (analysis/study/power.py labels them), and those it runs unless told
PLAN_TESTS: Final = ("mcnemar", "conditional_or", "wilcoxon", "mixed_model")
PLAN_DEFAULT_TESTS: Final = PLAN_TESTS[:3]
# `--pilot`: bootstrap refits of the pilot's fit, one drawn per simulated study (an EM refit of an
# 8-participant pilot takes seconds, a counts refit a few hundredths)
PILOT_BOOTSTRAP = 50

# live studies (`trustroute live`, harness/live/server.py ServerOptions)
LIVE_CONNECTIONS_PER_BROWSER = 8    # a station: its 2 websockets, the 6 HTTP connections a browser keeps
LIVE_PACE = 1.0                      # simulated seconds per wall-clock second (1: real time)
LIVE_RESUME_WITHIN = 120.0           # seconds a disconnected participant has to resume an episode
LIVE_WARM_UP = True                  # a warm-up drive before each participant's trials

# fitting (`trustroute fit`, analysis/fitting/driver_model.py fit_study)
FIT_METHODS: Final = ("auto", "counts", "em")   # counts: reports are exact trust; em: noisy
FIT_METHOD: Final = "auto"           # counts when the study's reports are exact and on every road
FIT_ITERATIONS = 200                 # EM iterations at most
FIT_RESTARTS = 5                     # `--types`: seeded EM restarts per number of types K
FIT_MAX_TYPES = 4                    # `--types auto`: the largest K tried
