"""Fitting a finite mixture of driver models to a study's logs: driver types by EM over participants.

Each participant belongs to one latent type; all of a participant's episodes share it. Type k is a
full driver model (the hidden Markov model of analysis/fitting/driver_model.py: initial trust,
takeover and failure probabilities, trust-transition rows), all types share the report accuracy
(the report noise is a property of the display and the question, docs/driver_type_studies.md).
EM alternates:

- E-step: per type, the forward pass (analysis/fitting/forward_backward.py) gives every episode's
  log-likelihood; a participant's is the sum over their episodes; responsibilities
  r[p, k] ∝ w_k · exp(loglik[p, k]);
- M-step: the type's backward pass, with every episode weighted by its participant's
  responsibility, gives its expected statistics, and driver_model.py's `maximisation` turns them into
  the type's model with the same regularisation as `trustroute fit` (MIN_ROW_WEIGHT, the takeover
  prior); w_k is the mean responsibility; the shared accuracy is fitted on the pooled report counts.

With one type this is exactly `trustroute fit --method em` (tests/analysis/fitting/test_mixture.py).
EM stops when the log-likelihood improves by less than EM_TOLERANCE per road (`converged`), else at
the iteration cap (reported). Several restarts from seeded random partitions of the
participants, and one from the best K-1 fit with its largest type split in two; the best
log-likelihood among converged restarts wins. The number of types is chosen by BIC with the
number of participants (the independent units) as the sample size; `bootstrap_type_count`
resamples participants for the chosen K's frequency and the weights' intervals.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment
from scipy.special import logsumexp

from trustroute.analysis.fitting.driver_model import (
    EM_TOLERANCE,
    MIN_ROW_WEIGHT,
    FitResult,
    Observations,
    Parameters,
    fit_accuracy,
    maximisation,
    observations_from_roads,
    starting_parameters,
)
from trustroute.analysis.fitting.forward_backward import Forward, backward, forward
from trustroute.analysis.study_directory import load_study, study_inputs
from trustroute.core import defaults
from trustroute.core.dataset import EPISODES_FILE, ROADS_FILE
from trustroute.core.errors import InputError
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import DriverPopulation, DriverType

DEFAULT_RESTARTS = defaults.FIT_RESTARTS
DEFAULT_MAX_TYPES = defaults.FIT_MAX_TYPES
START_HARDNESS = 0.8  # weight of the random partition in a restart's starting responsibilities
RESPONSIBILITY_FLOOR = 1e-200  # keeps an emptied type's statistics finite (its rows stay at the start)


@dataclass(frozen=True, eq=False)
class StudyLogs:
    """A study's logged roads and episodes (one row per episode, with its participant), and the
    driver model they were logged with (the template every fitted type's shape follows)."""

    roads: pd.DataFrame
    episodes: pd.DataFrame
    template: DriverModel


@dataclass(frozen=True, eq=False)
class ParticipantObservations:
    """The observations of a study's roads with the participant each episode belongs to:
    `owner[i]` is the row in `participants` (ids, sorted) of observation row i's participant."""

    observations: Observations
    owner: np.ndarray
    participants: list
    template: DriverModel


@dataclass(frozen=True)
class EMSettings:
    """How EM fits a mixture: `restarts` runs from random partitions (the best converged wins),
    at most `iterations` iterations each, and whether the types share their trust dynamics."""

    restarts: int = DEFAULT_RESTARTS
    iterations: int = 500
    shared_dynamics: bool = False


DEFAULT_EM = EMSettings()


@dataclass
class MixtureFit:
    """One fitted mixture of `n_types` driver models."""

    n_types: int
    weights: np.ndarray  # [K] prior weights, sum 1
    components: list[FitResult]  # per type: the driver model as driver_model.py's FitResult
    responsibilities: np.ndarray  # [P, K] posterior type probabilities per participant
    participants: list  # participant ids, in the rows of `responsibilities`
    loglik: float
    iterations: int
    converged: bool
    report_accuracy: float
    roads: int
    free_parameters: int
    restarts: int = 1
    restarts_converged: int = 1
    history: list[float] = field(default_factory=list)
    source: str = ""
    shared_dynamics: bool = False  # the types share their trust-transition rows

    @property
    def bic(self) -> float:
        """-2 loglik + d · ln(participants): the criterion that picks K."""
        return -2.0 * self.loglik + self.free_parameters * math.log(len(self.participants))

    @property
    def bic_roads(self) -> float:
        """The same with the number of roads as the sample size (a lighter penalty; shown beside)."""
        return -2.0 * self.loglik + self.free_parameters * math.log(max(self.roads, 1))

    def type_names(self) -> list[str]:
        return [f"type{k + 1}" for k in range(self.n_types)]

    def models(self) -> list[DriverModel]:
        return [component.model() for component in self.components]

    def hard_assignment(self) -> dict:
        """participant -> the name of its most probable type."""
        names = self.type_names()
        return {p: names[int(k)] for p, k in zip(self.participants, self.responsibilities.argmax(axis=1),
                                                 strict=True)}

    def summary(self) -> dict:
        names = self.type_names()
        return {
            "types": self.n_types,
            "shared_dynamics": self.shared_dynamics,
            "weights": dict(zip(names, self.weights.tolist(), strict=True)),
            "loglik": self.loglik,
            "free_parameters": self.free_parameters,
            "bic": self.bic,
            "bic_roads": self.bic_roads,
            "iterations": self.iterations,
            "converged": self.converged,
            "restarts": self.restarts,
            "restarts_converged": self.restarts_converged,
            "report_accuracy": self.report_accuracy,
            "participants": len(self.participants),
            "roads": self.roads,
            "participants_per_type": {
                name: int((self.responsibilities.argmax(axis=1) == k).sum()) for k, name in enumerate(names)
            },
            "mean_max_responsibility": float(self.responsibilities.max(axis=1).mean()),
            "unidentified_rows": {name: len(c.sparse_rows()) for name, c in zip(names, self.components,
                                                                                 strict=True)},
        }


def participant_index(obs: Observations, episodes: pd.DataFrame) -> tuple[np.ndarray, list]:
    """(participant row of each observation row, participant ids in row order)."""
    of_episode = dict(zip(episodes["episode_id"].astype(str), episodes["participant"], strict=True))
    missing = [e for e in obs.episode_ids if e not in of_episode]
    if missing:
        raise InputError(str(Path(obs.source).with_name(EPISODES_FILE)), "participant",
                         f"episode {missing[0]!r} of the roads has no participant",
                         "rebuild the study's dataset")
    ids = sorted({of_episode[e] for e in obs.episode_ids})
    row_of = {p: i for i, p in enumerate(ids)}
    return np.array([row_of[of_episode[e]] for e in obs.episode_ids], dtype=np.int64), ids


def participant_observations(logs: StudyLogs) -> ParticipantObservations:
    """The logs' observations (analysis/fitting/driver_model.py) with each episode's participant."""
    obs = observations_from_roads(logs.roads, logs.template)
    owner, participants = participant_index(obs, logs.episodes)
    return ParticipantObservations(obs, owner, participants, logs.template)


def free_parameters(components: list[FitResult], n_trust: int, shared_dynamics: bool = False) -> int:
    """Estimated parameters: per type π (k-1), every non-structural takeover and failure entry,
    k-1 per transition row with enough data (rows below MIN_ROW_WEIGHT stay at the start value and
    are not estimated; shared rows counted once); K-1 weights; the shared report accuracy."""
    total = (len(components) - 1) + 1  # K-1 weights, the shared report accuracy
    for index, c in enumerate(components):
        p = c.parameters
        total += n_trust - 1
        total += int((p.takeover > 0).sum()) + int((p.failure > 0).sum())
        if index == 0 or not shared_dynamics:
            total += int((c.row_weight >= MIN_ROW_WEIGHT).sum()) * (n_trust - 1)
    return total


def _participant_loglik(passes: list[Forward], owner: np.ndarray, n_participants: int) -> np.ndarray:
    """[P, K] log-likelihood of each participant's episodes under each type (from each type's
    forward pass)."""
    out = np.empty((n_participants, len(passes)))
    for k, fwd in enumerate(passes):
        out[:, k] = np.bincount(owner, weights=fwd.episode_loglik, minlength=n_participants)
    return out


def _posterior(log_weights: np.ndarray, loglik: np.ndarray) -> tuple[np.ndarray, float]:
    joint = log_weights[None, :] + loglik
    norm = logsumexp(joint, axis=1)
    return np.exp(joint - norm[:, None]), float(norm.sum())


def _pooled_dynamics(stats: list) -> list:
    """Every type's statistics with the transition counts pooled over types (shared rows)."""
    pooled = sum(s.transition for s in stats)
    return [replace(s, transition=pooled) for s in stats]


def _run_em(data: ParticipantObservations, responsibilities: np.ndarray, settings: EMSettings,
            start: list[Parameters] | None = None) -> MixtureFit:
    obs, owner, template = data.observations, data.owner, data.template
    n_participants, shared_dynamics = len(data.participants), settings.shared_dynamics
    n_inc, k_trust = len(template.incident_types), template.n_trust
    n_types = responsibilities.shape[1]
    params = ([copy_parameters(p) for p in start] if start is not None
              else [starting_parameters(n_inc, k_trust, obs) for _ in range(n_types)])
    weights = responsibilities.mean(axis=0)
    history: list[float] = []
    converged = False
    stats = []
    # a type's forward pass serves its participants' log-likelihoods and then, unchanged (it does
    # not depend on the responsibilities), the next iteration's weighted statistics
    passes = [forward(obs, p) for p in params]
    for _ in range(settings.iterations):
        r = np.maximum(responsibilities, RESPONSIBILITY_FLOOR)
        stats = [backward(obs, params[k], passes[k], weights=r[owner, k]) for k in range(n_types)]
        if shared_dynamics:
            stats = _pooled_dynamics(stats)
        accuracy = fit_accuracy(sum((s.report for s in stats), np.zeros((k_trust, k_trust))), k_trust)
        params = [maximisation(stats[k], params[k], accuracy) for k in range(n_types)]
        weights = responsibilities.mean(axis=0)
        with np.errstate(divide="ignore"):
            log_weights = np.log(weights)
        passes = [forward(obs, p) for p in params]
        responsibilities, loglik = _posterior(log_weights, _participant_loglik(passes, owner, n_participants))
        history.append(loglik)
        if len(history) > 1 and history[-1] - history[-2] < EM_TOLERANCE * max(1, obs.steps):
            converged = True
            break
    # The statistics of the final parameters, weighted by the final responsibilities: each type's
    # expected visits (which rows it identifies).
    r = np.maximum(responsibilities, RESPONSIBILITY_FLOOR)
    final = [backward(obs, params[k], passes[k], weights=r[owner, k]) for k in range(n_types)]
    if shared_dynamics:
        final = _pooled_dynamics(final)
    weights = responsibilities.mean(axis=0)
    components = [
        FitResult(
            method="em-mixture",
            template=template,
            parameters=params[k],
            episodes=int(round(float(r[owner, k].sum()))),
            transitions=int(round(float((obs.mask * r[owner, k][:, None]).sum()))),
            iterations=len(history),
            loglik=history[-1] if history else float("nan"),
            row_weight=final[k].transition.sum(axis=-1),
            report_accuracy=params[k].accuracy,
            converged=converged,
            takeover_weight=final[k].visits,
        )
        for k in range(n_types)
    ]
    fit = MixtureFit(
        n_types=n_types, weights=weights, components=components, responsibilities=responsibilities,
        participants=list(range(n_participants)), loglik=history[-1] if history else float("nan"),
        iterations=len(history), converged=converged, report_accuracy=float(params[0].accuracy),
        roads=obs.steps, free_parameters=free_parameters(components, k_trust, shared_dynamics),
        history=history, shared_dynamics=shared_dynamics,
    )
    return _ordered(fit)


def _ordered(fit: MixtureFit) -> MixtureFit:
    """Types by weight, largest first (ties: by mean takeover probability), so names are stable."""
    key = [(-w, -float(c.parameters.takeover.mean())) for w, c in zip(fit.weights, fit.components,
                                                                      strict=True)]
    order = sorted(range(fit.n_types), key=lambda k: key[k])
    fit.weights = fit.weights[order]
    fit.components = [fit.components[k] for k in order]
    fit.responsibilities = fit.responsibilities[:, order]
    return fit


def copy_parameters(p: Parameters) -> Parameters:
    return Parameters(initial=p.initial.copy(), takeover=p.takeover.copy(), failure=p.failure.copy(),
                      transition=p.transition.copy(), accuracy=p.accuracy)


def split_start(previous: MixtureFit, rng: np.random.Generator) -> tuple[np.ndarray, list[Parameters]]:
    """A K+1 start from a K-type fit: the largest type's participants split at random between it
    and a copy of it (so EM starts at the K-type optimum and can only move away from it to gain)."""
    largest = int(np.argmax(previous.weights))
    r = np.concatenate([previous.responsibilities, np.zeros((len(previous.participants), 1))], axis=1)
    moved = rng.random(len(previous.participants)) < 0.5
    r[moved, -1] = r[moved, largest]
    r[moved, largest] = 0.0
    params = [c.parameters for c in previous.components]
    return r, [*params, params[largest]]


def fit_mixture(data: ParticipantObservations, n_types: int, rng: np.random.Generator,
                settings: EMSettings = DEFAULT_EM, previous: MixtureFit | None = None) -> MixtureFit:
    """The best of `settings.restarts` EM runs (one for a single type: there is nothing to
    restart), plus one run split from `previous` (a fit with one type fewer) when given.
    `settings.shared_dynamics`: the types share the trust-transition rows (fitted on all
    participants) and differ in initial trust, takeover and failure probabilities."""
    if n_types < 1:
        raise ValueError(f"n_types must be >= 1, got {n_types}")
    n_participants = len(data.participants)
    if n_types > n_participants:
        raise InputError("--types", "", f"{n_types} types for {n_participants} participants",
                         "fit at most one type per participant")
    runs = []
    for _ in range(1 if n_types == 1 else max(1, settings.restarts)):
        # a random partition of the participants, softened (a soft uniform start keeps the types
        # alike for many iterations and ends in poorer optima)
        hard = np.eye(n_types)[rng.integers(n_types, size=n_participants)]
        start = START_HARDNESS * hard + (1 - START_HARDNESS) * rng.dirichlet(np.ones(n_types),
                                                                             size=n_participants)
        runs.append(_run_em(data, start, settings))
    if previous is not None and previous.n_types == n_types - 1:
        responsibilities, params = split_start(previous, rng)
        runs.append(_run_em(data, responsibilities, settings, start=params))
    converged = [r for r in runs if r.converged]
    best = max(converged or runs, key=lambda r: r.loglik)
    best.participants = list(data.participants)
    best.restarts, best.restarts_converged = len(runs), len(converged)
    return best


@dataclass
class TypeSelection:
    """Mixtures for K = 1..max_types and the K chosen by BIC (n = participants), or the one fit of
    a K given."""

    fits: list[MixtureFit]
    chosen: int

    @property
    def best(self) -> MixtureFit:
        return next(f for f in self.fits if f.n_types == self.chosen)

    def table(self) -> list[dict]:
        lowest = min(f.bic for f in self.fits)
        return [
            {
                "types": f.n_types,
                "loglik": f.loglik,
                "free_parameters": f.free_parameters,
                "bic": f.bic,
                "delta_bic": f.bic - lowest,
                "bic_roads": f.bic_roads,
                "converged": f.converged,
                "restarts_converged": f"{f.restarts_converged}/{f.restarts}",
                "iterations": f.iterations,
                "weights": f.weights.tolist(),
            }
            for f in self.fits
        ]


def select_types(data: ParticipantObservations, max_types: int, rng: np.random.Generator,
                 settings: EMSettings = DEFAULT_EM,
                 progress: Callable[[], None] | None = None) -> TypeSelection:
    """Fit K = 1..max_types (each K also from a split of the best K-1 fit); choose the K with the
    lowest BIC."""
    fits: list[MixtureFit] = []
    for k in range(1, min(max_types, len(data.participants)) + 1):
        fits.append(fit_mixture(data, k, rng, settings, previous=fits[-1] if fits else None))
        if progress is not None:
            progress()
    chosen = 1 + int(np.argmin([f.bic for f in fits]))
    return TypeSelection(fits=fits, chosen=chosen)


def _resampled(roads: pd.DataFrame, episodes: pd.DataFrame, drawn: np.ndarray,
               participants: list) -> tuple[pd.DataFrame, pd.DataFrame]:
    by_participant = {p: list(g["episode_id"]) for p, g in episodes.groupby("participant")}
    grouped = {e: g for e, g in roads.groupby("episode_id")}
    road_parts, episode_rows = [], []
    for copy, index in enumerate(drawn):
        for episode_id in by_participant[participants[index]]:
            new_id = f"{episode_id}#{copy}"
            road_parts.append(grouped[episode_id].assign(episode_id=new_id))
            episode_rows.append({"episode_id": new_id, "participant": copy})
    return pd.concat(road_parts, ignore_index=True), pd.DataFrame(episode_rows)


def _takeover_signature(fit: MixtureFit) -> np.ndarray:
    return np.stack([c.parameters.takeover.ravel() for c in fit.components])


def bootstrap_type_count(logs: StudyLogs, selection: TypeSelection, max_types: int, resamples: int,
                         rng: np.random.Generator, settings: EMSettings = DEFAULT_EM,
                         progress: Callable[[], None] | None = None, choose: bool = True) -> dict:
    """Participants resampled with replacement (all their episodes together), K chosen again by BIC
    (`choose`; else K stays the selection's): how often each K wins; and, refitting the chosen K,
    2.5/97.5 percentiles of each type's weight and takeover probabilities, the resample's types
    matched to the fit's by their takeover probabilities (Hungarian assignment, so labels cannot
    switch)."""
    roads, episodes, template = logs.roads, logs.episodes, logs.template
    participants = sorted(episodes["participant"].unique())
    chosen = selection.chosen
    reference = _takeover_signature(selection.best)
    wins = np.zeros(min(max_types, len(participants)), dtype=int)
    weights, takeovers, converged = [], [], 0
    for _ in range(resamples):
        drawn = rng.choice(len(participants), size=len(participants), replace=True)
        sample = participant_observations(StudyLogs(*_resampled(roads, episodes, drawn, participants),
                                                    template))
        if choose:
            result = select_types(sample, max_types, rng, settings)
            wins[result.chosen - 1] += 1
            fit = result.fits[chosen - 1] if chosen <= len(result.fits) else None
        else:
            fit = fit_mixture(sample, chosen, rng, settings)
        if fit is not None:
            converged += bool(fit.converged)
            cost = ((reference[:, None, :] - _takeover_signature(fit)[None, :, :]) ** 2).sum(axis=-1)
            _, match = linear_sum_assignment(cost)
            weights.append(fit.weights[match])
            takeovers.append(np.stack([fit.components[j].parameters.takeover for j in match]))
        if progress is not None:
            progress()
    names = selection.best.type_names()
    out: dict = {"resamples": resamples, "unit": "participant", "types": chosen,
                 "refits_converged": converged}
    if choose:
        out.update({
            "criterion": "BIC (n = participants)",
            "chosen_types_frequency": {str(k + 1): int(w) for k, w in enumerate(wins)},
            "chosen_types_share": float(wins[chosen - 1] / resamples) if resamples else None,
        })
    if weights:
        w = np.stack(weights)
        t = np.stack(takeovers)  # [B, K, I, k]
        out["weights"] = {name: {"low": float(np.percentile(w[:, j], 2.5)),
                                 "high": float(np.percentile(w[:, j], 97.5))}
                          for j, name in enumerate(names)}
        out["takeover_probability"] = {
            name: {inc: {"low": np.percentile(t[:, j, i], 2.5, axis=0).tolist(),
                         "high": np.percentile(t[:, j, i], 97.5, axis=0).tolist()}
                   for i, inc in enumerate(template.incident_types)}
            for j, name in enumerate(names)
        }
    return out


def mixture_population(fit: MixtureFit, source: str, provenance: str):
    """The fitted mixture as a driver population (participants/driver_population.py)."""
    types = tuple(
        DriverType(name=name, weight=float(w), model=model)
        for name, w, model in zip(fit.type_names(), fit.weights, fit.models(), strict=True)
    )
    return DriverPopulation(types=types, source_path=source, provenance=provenance)


def study_observations(study_dir) -> tuple[ParticipantObservations, StudyLogs]:
    """A study's observations with each episode's participant, and its logs."""
    manifest, episodes, roads = load_study(Path(study_dir))
    _, template, _ = study_inputs(manifest, study_dir)
    logs = StudyLogs(roads, episodes, template)
    obs = observations_from_roads(roads, template, str(Path(study_dir) / ROADS_FILE))
    if obs.steps == 0:
        raise InputError(obs.source, "", "no roads driven in the logs",
                         "run a study with episodes first")
    owner, participants = participant_index(obs, episodes)
    return ParticipantObservations(obs, owner, participants, template), logs
