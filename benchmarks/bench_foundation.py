"""Foundation throughput: the exact Bayes belief filter and the synthetic driver.

- `belief_filter_vectorised`: beliefs updated per second by `TrustPOMDP.belief_update` on one
  batch of 10^5 beliefs with random (incident, h, e), against a baseline measured in the same
  run: the same update applied belief by belief in a Python loop (one vector-matrix product and
  a normalisation per belief, as an online filter would do). Both are checked to agree first.
- `synthetic_driver_steps`: incident steps per second of `SyntheticDriver` (takeover decision,
  performance, trust move, report), the per-road cost of the human in the model engine.
Sizes keep the run to a few seconds on a shared 2-core machine.
"""

from __future__ import annotations

import numpy as np

from benchmarks.timing import best_seconds
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.model.trust_pomdp import build_pomdp

BATCH = 100_000
LOOP = 20_000
DRIVER_STEPS = 20_000


def _loop_update(weighted: np.ndarray, beliefs: np.ndarray, inc: np.ndarray, h: np.ndarray,
                 e: np.ndarray) -> np.ndarray:
    out = np.empty_like(beliefs)
    for k in range(beliefs.shape[0]):
        row = beliefs[k] @ weighted[inc[k], h[k], e[k]]
        total = row.sum()
        out[k] = row / total if total > 0 else 0.0
    return out


def run() -> list[dict]:
    pomdp = build_pomdp(load_town(), load_driver_model())
    rng = np.random.default_rng(0)
    beliefs = rng.dirichlet(np.ones(pomdp.n_trust), size=BATCH)
    inc = rng.integers(0, len(pomdp.driver.incident_types), size=BATCH)
    h = rng.integers(0, 2, size=BATCH)
    e = np.zeros(BATCH, dtype=np.int64)

    vectorised = pomdp.belief_update(beliefs, inc, h, e)[0]
    looped = _loop_update(pomdp.weighted_transition, beliefs[:LOOP], inc[:LOOP], h[:LOOP], e[:LOOP])
    if not np.allclose(vectorised[:LOOP], looped, rtol=1e-12, atol=1e-15):
        raise AssertionError("vectorised and looped belief updates disagree")

    batch_seconds = best_seconds(lambda: pomdp.belief_update(beliefs, inc, h, e), repeats=5)
    loop_seconds = best_seconds(
        lambda: _loop_update(pomdp.weighted_transition, beliefs[:LOOP], inc[:LOOP], h[:LOOP], e[:LOOP]),
        repeats=3)
    rate = BATCH / batch_seconds
    baseline = LOOP / loop_seconds

    incidents = [pomdp.driver.incident_types[i] for i in rng.integers(0, 4, size=DRIVER_STEPS)]

    def drive() -> None:
        person = SyntheticDriver(pomdp.driver, np.random.default_rng(1))
        for incident in incidents:
            took_over = person.decides_takeover(incident)
            performance = person.performance(incident)
            person.move_trust(incident, took_over, performance)
            person.report_trust()

    driver_seconds = best_seconds(drive, repeats=3)
    return [
        {"name": "belief_filter_vectorised", "value": rate, "unit": "beliefs/s",
         "baseline": baseline, "ratio": rate / baseline, "batch": BATCH,
         "baseline_what": "per-belief Python loop of the same update"},
        {"name": "synthetic_driver_steps", "value": DRIVER_STEPS / driver_seconds, "unit": "steps/s"},
    ]
