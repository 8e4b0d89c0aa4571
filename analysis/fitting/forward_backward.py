"""The E-step of the driver model's EM (analysis/fitting/driver_model.py): forward-backward over
every episode at once, scaled, and the expected sufficient statistics.

The forward pass depends on the parameters only, so it is a value of its own (`Forward`): the
mixture's EM (analysis/fitting/mixture.py) computes it once per type and iteration, for the
participants' log-likelihoods and then for the weighted statistics of the next M-step.

Every sum adds its terms in one fixed order, that of a plain numpy reduction, so a fit is the same
to the last bit: over trust levels as `.sum(axis=...)` does (`_level_sum`), over roads one road
after the other in row order (`np.bincount`, and the last row of `np.cumsum`); a padded step is
the identity and is skipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.core.dataset import ROADS_FILE
from trustroute.participants.driver_model import report_matrix

PAIRWISE_FROM = 8  # numpy's sums of this many terms or more along a contiguous axis are pairwise


@dataclass(frozen=True)
class Observations:
    """Padded per-episode sequences: steps t = 1..L (roads after the start)."""

    incident: np.ndarray  # int [n, S] driver-model incident index (0 on padding)
    takeover: np.ndarray  # int [n, S]
    performance: np.ndarray  # int [n, S]
    report: np.ndarray  # int [n, S+1] trust index reported after step t (column 0: at the start), -1 none
    mask: np.ndarray  # bool [n, S] step exists
    episode_ids: tuple[str, ...] = ()  # the episode of each row, in row order (sorted ids)
    source: str = ROADS_FILE  # the roads table they were read from, named in errors

    @property
    def episodes(self) -> int:
        return int(self.mask.shape[0])

    @property
    def steps(self) -> int:
        return int(self.mask.sum())


@dataclass
class Parameters:
    initial: np.ndarray  # [k]
    takeover: np.ndarray  # [I, k]
    failure: np.ndarray  # [I, k]
    transition: np.ndarray  # [I, 2, 2, k, k]
    accuracy: float


@dataclass
class Statistics:
    loglik: float
    initial: np.ndarray
    takeover_num: np.ndarray
    failure_num: np.ndarray
    visits: np.ndarray  # [I, k] expected trust-before counts per incident
    transition: np.ndarray  # [I, 2, 2, k, k] expected transition counts
    report: np.ndarray  # [k, k] expected (θ, r) counts
    episode_loglik: np.ndarray | None = None  # [n] log-likelihood of each episode


@dataclass(frozen=True)
class Forward:
    """The scaled forward pass of one set of parameters over the observations. A padded step's
    matrix is the identity (it moves nothing), so only the driven roads' matrices are kept."""

    alpha: np.ndarray  # [n, S+1, k] scaled forward probabilities
    scale: np.ndarray  # [n, S+1] the scale factors (their logs sum to the log-likelihood)
    active: list[np.ndarray]  # per step t: the rows (episodes) that drive a road at t, ascending
    matrices: list[np.ndarray]  # per step t: [len(active[t]), k, k] joint observation-transition matrices

    @property
    def episode_loglik(self) -> np.ndarray:
        return np.log(self.scale).sum(axis=1)


def _level_sum(terms: np.ndarray, axis: int) -> np.ndarray:
    """`terms.sum(axis=axis)`, to the last bit. numpy adds fewer than PAIRWISE_FROM terms one after
    the other, as this does level by level (without numpy's per-row reduction loop); more along
    the last axis in its own pairwise order, so those are left to it."""
    if terms.shape[axis] >= PAIRWISE_FROM:
        return terms.sum(axis=axis)
    first = np.moveaxis(terms, axis, 0)
    out = first[0].copy()
    for level in first[1:]:
        out += level
    return out


def forward(obs: Observations, p: Parameters) -> Forward:
    n, steps = obs.mask.shape
    k = p.initial.size
    R = report_matrix(p.accuracy, k)
    emission = np.ones((n, steps + 1, k))
    has = obs.report >= 0
    emission[has] = R[:, obs.report[has]].T
    # P(h | θ) P(e | θ) T[inc][h][e](θ, ·) per (inc, h, e): the same products a road's gathers give
    p_h = np.stack([1 - p.takeover, p.takeover], axis=1)  # [I, 2, k]
    p_e = np.stack([1 - p.failure, p.failure], axis=1)
    like = p_h[:, :, None, :] * p_e[:, None, :, :]  # [I, 2, 2, k]
    joint = (like[..., None] * p.transition).reshape(-1, k, k)
    group = (obs.incident * 2 + obs.takeover) * 2 + obs.performance  # [n, S]
    active = [np.flatnonzero(obs.mask[:, t]) for t in range(steps)]
    matrices = []
    alpha = np.zeros((n, steps + 1, k))
    scale = np.ones((n, steps + 1))
    a0 = p.initial[None, :] * emission[:, 0]
    scale[:, 0] = a0.sum(axis=1)
    alpha[:, 0] = a0 / scale[:, 0:1]
    for t in range(steps):
        rows = active[t]
        M = joint[group[rows, t]]
        M *= emission[rows, t + 1, None, :]
        matrices.append(M)
        a = alpha[:, t].copy()  # a padded row: α times the identity, exactly α
        a[rows] = np.einsum("ni,nij->nj", alpha[rows, t], M)
        s = a.sum(axis=1)
        s = np.where(s > 0, s, 1e-300)
        scale[:, t + 1] = s
        alpha[:, t + 1] = a / s[:, None]
    return Forward(alpha=alpha, scale=scale, active=active, matrices=matrices)


def _with_identity(M: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray:
    """[n, k, k] the step's matrices: `M` on the driven `rows`, the identity on the others."""
    full = np.broadcast_to(np.eye(M.shape[-1]), (n, *M.shape[1:])).copy()
    full[rows] = M
    return full


def _backward_step(M: np.ndarray, rows: np.ndarray, beta: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """β of the step before: the matrices `M` of the driven `rows`, the identity elsewhere (a
    non-finite β, after an impossible observation, goes through the identity's zeros as NaN)."""
    if not np.isfinite(beta).all():
        return np.einsum("nij,nj->ni", _with_identity(M, rows, beta.shape[0]), beta) / scale[:, None]
    out = beta / scale[:, None]
    out[rows] = np.einsum("nij,nj->ni", M, beta[rows]) / scale[rows, None]
    return out


def _every_road_step(obs: Observations, fwd: Forward, t: int, beta: np.ndarray, weight: np.ndarray,
                     groups: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Step t's (transition counts per group, posterior of θ_{t-1} per row, reported levels, their
    posteriors of θ_t) over every row, padded ones included with their identity and weight 0: where
    a value is not finite (an impossible observation), its zero-weighted products are NaN and
    spread as they do through these sums."""
    n, k = beta.shape
    mask = obs.mask[:, t]
    M = _with_identity(fwd.matrices[t], fwd.active[t], n)
    xi = fwd.alpha[:, t, :, None] * M * beta[:, None, :] / fwd.scale[:, t + 1, None, None]
    xi *= (mask * weight)[:, None, None]
    onehot = np.zeros((n, groups))
    g = (obs.incident[:, t] * 2 + obs.takeover[:, t]) * 2 + obs.performance[:, t]
    onehot[np.arange(n), g] = mask
    reports = obs.report[:, t + 1]
    has = (reports >= 0) & mask
    return (np.einsum("ng,nij->gij", onehot, xi), xi.sum(axis=2), reports[has], xi.sum(axis=1)[has])


def _ordered_report_counts(reports: list[np.ndarray], posteriors: list[np.ndarray], k: int) -> np.ndarray:
    """[k, k] Σ posterior[θ] over the roads reporting r, each (θ, r) sum in the order given."""
    levels = np.concatenate(reports)
    rows = np.concatenate(posteriors)
    counts = np.zeros((k, k))
    for r in range(k):
        chosen = rows[levels == r]
        if chosen.size:
            counts[:, r] = np.cumsum(chosen, axis=0)[-1]
    return counts


def backward(obs: Observations, p: Parameters, fwd: Forward, weights: np.ndarray | None = None) -> Statistics:
    """The expected sufficient statistics given the forward pass `fwd` of `p` (see `expectation`)."""
    n, steps = obs.mask.shape
    weight = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    k = p.initial.size
    inc, h, e, mask = obs.incident, obs.takeover, obs.performance, obs.mask
    alpha, scale = fwd.alpha, fwd.scale
    beta = np.ones((n, k))
    stats_transition = np.zeros_like(p.transition)
    visits = np.zeros_like(p.takeover)
    take_num = np.zeros_like(p.takeover)
    fail_num = np.zeros_like(p.failure)
    groups = p.transition.shape[0] * 4
    rows = np.arange(n)
    group = (inc * 2 + h) * 2 + e  # [n, S]
    cell = np.arange(k * k)
    inc_hot = np.zeros((n, p.takeover.shape[0]))
    before = np.zeros((n, k))
    reported, posteriors = [], []
    for t in range(steps - 1, -1, -1):
        # Only the roads driven at step t carry statistics (a padded step's ξ is 0): ξ of those
        # rows, in row order
        active, M = fwd.active[t], fwd.matrices[t]
        xi = alpha[active, t, :, None] * M
        xi *= beta[active, None, :]
        xi /= scale[active, t + 1, None, None]
        xi *= weight[active, None, None]
        beta_before = _backward_step(M, active, beta, scale[:, t + 1])
        if np.isfinite(beta).all() and np.isfinite(xi).all() and np.isfinite(beta_before).all():
            # Σ over the roads of each (inc, h, e) group, road by road (bincount adds in row order)
            cells = (group[active, t][:, None] * (k * k) + cell).ravel()
            per_group = np.bincount(cells, weights=xi.ravel(), minlength=groups * k * k)
            before.fill(0.0)
            before[active] = _level_sum(xi, axis=2)  # posterior of θ_{t-1}
            reports = obs.report[active, t + 1]
            has = reports >= 0
            reported.append(reports[has])
            posteriors.append(_level_sum(xi[has], axis=1))  # posterior of θ_t
        else:
            per_group, before, levels, after = _every_road_step(obs, fwd, t, beta, weight, groups)
            reported.append(levels)
            posteriors.append(after)
        stats_transition += per_group.reshape(stats_transition.shape)
        inc_hot.fill(0.0)
        inc_hot[rows, inc[:, t]] = mask[:, t]
        visits += inc_hot.T @ before
        take_num += (inc_hot * h[:, t, None]).T @ before
        fail_num += (inc_hot * e[:, t, None]).T @ before
        beta = beta_before
    gamma0 = alpha[:, 0] * beta
    gamma0 /= gamma0.sum(axis=1, keepdims=True)
    gamma0 *= weight[:, None]
    has0 = obs.report[:, 0] >= 0
    reported.append(obs.report[has0, 0])
    posteriors.append(gamma0[has0])
    episode_loglik = fwd.episode_loglik
    return Statistics(
        loglik=float(episode_loglik.sum()),
        initial=gamma0.sum(axis=0),
        takeover_num=take_num,
        failure_num=fail_num,
        visits=visits,
        transition=stats_transition,
        report=_ordered_report_counts(reported, posteriors, k),
        episode_loglik=episode_loglik,
    )


def expectation(obs: Observations, p: Parameters, weights: np.ndarray | None = None) -> Statistics:
    """Forward-backward over every episode at once (scaled), expected sufficient statistics.

    `weights` [n] (default 1) scale each episode's contribution to the statistics: a mixture's
    responsibility of this model for the episode's participant (analysis/fitting/mixture.py). The
    log-likelihoods (total and per episode) are unweighted."""
    return backward(obs, p, forward(obs, p), weights)


def initial_posterior(obs: Observations, p: Parameters) -> tuple[np.ndarray, float]:
    """(Σ over episodes of the posterior of θ_0, the log-likelihood): the part of `expectation`
    that fitting π alone needs, without the other statistics."""
    fwd = forward(obs, p)
    beta = np.ones((obs.mask.shape[0], p.initial.size))
    for t in range(obs.mask.shape[1] - 1, -1, -1):
        beta = _backward_step(fwd.matrices[t], fwd.active[t], beta, fwd.scale[:, t + 1])
    gamma0 = fwd.alpha[:, 0] * beta
    gamma0 /= gamma0.sum(axis=1, keepdims=True)
    return gamma0.sum(axis=0), float(fwd.episode_loglik.sum())
