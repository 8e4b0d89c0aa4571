"""The synthetic driver's step: the one definition of every draw of a simulated driver.

Owns the draws of a step from `DriverTables` (participants/driver_model.py: the probability tables
of one or more driver models on one incident list; a model holds its own, `DriverModel.tables`), in
the order a road is driven:

1. `draw_takeovers`: h ~ P(takeover | θ, inc), from the trust before the road;
2. `draw_performances`: the AV's performance e ~ P(fail | θ, inc) (the SUMO engine measures e
   instead of drawing it);
3. `draw_trust`: θ' ~ T[inc][h][e](θ, ·);
4. `draw_reports`: the report of θ' through the driver model's noise model (`draw_report`);
   `draw_report_batch` draws the same model for many drivers at once (in distribution).

`draw_step` is 1-3 in that order; `draw_initial_trust` draws θ_0. Every function takes either one
driver (integer indices) or arrays of drivers (kind, incident and trust indices broadcast
together). A draw of n drivers takes n uniforms from the Generator in driver order
(`rng.random(n)`), one driver takes one (`rng.random()`): the same stream, so a batch of one draws
exactly as the single driver does. Inverse-CDF draws compare u · total with the cumulative row
(robust to rows summing to 1 ± 1e-9); the cumulative rows are `np.cumsum` along the last axis,
which adds in the same order for every row of a stacked table as on the row alone.

Users: `participants.synthetic_driver.SyntheticDriver` (one driver, both engines), the model
engine's batch path and Monte Carlo (harness/simulation/model_engine.py), POUCT's search step
(policies/pomdp_py/pouct.py) and the posterior-predictive check's draws (trustroute/app/drivers.py,
`simulate`).
"""

from __future__ import annotations

import numpy as np

from trustroute.participants.driver_model import DriverTables, draw_report


def _bernoulli(p, rng: np.random.Generator):
    """1 with probability p, else 0, per driver (an int for one driver): u < p."""
    if np.ndim(p) == 0:
        return int(rng.random() < p)
    return (rng.random(np.shape(p)) < p).astype(np.int64)


def draw_rows(cdf: np.ndarray, rng: np.random.Generator):
    """One index per cumulative row of `cdf` [..., k] (an int for one row): the number of entries
    at most u · total, u uniform (inverse CDF, capped at k - 1)."""
    last = cdf.shape[-1] - 1
    if cdf.ndim == 1:
        # A cumulative row never decreases, so the count is a binary search (one call, no
        # temporary array: a SUMO episode draws a row per road, between simulation steps).
        return min(int(cdf.searchsorted(rng.random() * cdf[-1], side="right")), last)
    u = rng.random(cdf.shape[:-1]) * cdf[..., -1]
    return np.minimum((cdf <= u[..., None]).sum(axis=-1), last)


def draw_initial_trust(tables: DriverTables, kind, rng: np.random.Generator):
    """θ_0 ~ the initial distribution of each driver's kind."""
    return draw_rows(tables.initial_cdf[kind], rng)


def draw_takeovers(tables: DriverTables, kind, incident, theta, rng: np.random.Generator):
    """h ~ P(takeover | θ, incident): 1 takeover, 0 standstill."""
    return _bernoulli(tables.takeover[kind, incident, theta], rng)


def draw_performances(tables: DriverTables, kind, incident, theta, rng: np.random.Generator):
    """The AV's e ~ P(fail | θ, incident): 0 succ, 1 fail. One uniform per driver also where the
    model cannot fail, so models with and without failures consume the stream alike."""
    return _bernoulli(tables.failure[kind, incident, theta], rng)


def draw_trust(tables: DriverTables, kind, incident, h, e, theta, rng: np.random.Generator):
    """θ' ~ T[incident][h][e](θ, ·)."""
    return draw_rows(tables.transition_cdf[kind, incident, h, e, theta], rng)


def draw_step(tables: DriverTables, kind, incident, theta, rng: np.random.Generator):
    """One road: (h, e, θ') drawn in that order (takeover and performance from the trust before)."""
    h = draw_takeovers(tables, kind, incident, theta, rng)
    e = draw_performances(tables, kind, incident, theta, rng)
    return h, e, draw_trust(tables, kind, incident, h, e, theta, rng)


def draw_reports(theta, accuracy: float, n_trust: int, rng: np.random.Generator):
    """Reported trust indices of trust indices θ through the driver model's `draw_report`, driver by
    driver in order (a report takes one or two uniforms, so the draws cannot be batched)."""
    if np.ndim(theta) == 0:
        return draw_report(int(theta), accuracy, n_trust, rng)
    flat = [draw_report(t, accuracy, n_trust, rng) for t in np.asarray(theta).ravel().tolist()]
    return np.array(flat, dtype=np.int64).reshape(np.shape(theta))


def draw_report_batch(theta: np.ndarray, accuracy: float, n_trust: int,
                      rng: np.random.Generator) -> np.ndarray:
    """Reports of many drivers at once, from the noise model of `draw_report` (the true index with
    probability `accuracy`, else one level down or up with equal chance, clipped), in distribution:
    one uniform per driver, then one per driver whose report is off, each batch in driver order
    (the model engine's batch path; `draw_reports` draws as the single driver does)."""
    theta = np.asarray(theta, dtype=np.int64)
    off = rng.random(theta.shape) >= accuracy
    step = np.where(rng.random(int(off.sum())) < 0.5, -1, 1)
    out = theta.copy()
    out[off] = np.clip(theta[off] + step, 0, n_trust - 1)
    return out
