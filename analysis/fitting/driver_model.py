"""Fitting a driver model to a study's logs: trust dynamics, takeover model, report accuracy.

Only what a real study could observe is used: per road the incident, the takeover h, the AV's
performance e and the reported trust (when reported); the true trust columns of the logs are
never read. The model (docs/model.md, "The model") is a hidden Markov model over trust θ_t:
θ_0 ~ π; on road t, h_t ~ P(h | θ_{t-1}, inc_t), e_t ~ P(e | θ_{t-1}, inc_t),
θ_t ~ T[inc_t][h_t][e_t](θ_{t-1}, ·); the report r_t is θ_t with probability a, else one level
up or down (equal chance, clipped at the ends: the driver model's `report_matrix`).

- method "em": Baum-Welch (forward-backward with scaling, vectorised over episodes:
  analysis/fitting/forward_backward.py) for π, the takeover and failure probabilities, every T
  row and a. Rows with little expected data keep their starting value (a generic banded matrix)
  and are listed in `sparse_rows`.
- method "counts": reports are exact (a = 1) and given on every road, so θ_t = r_t for t >= 1
  and the rows are plain counts over the roads t >= 2 (θ_0 is never reported: π is then fitted
  by EM on θ_0 alone, with the counted model).
- method "auto": "counts" when the study's config says reports are exact and on every road
  (report accuracy 1, report_every 1), else "em".

Recovery on synthetic data: tests/analysis/fitting/test_driver_model.py (stated tolerances there).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.fitting.forward_backward import (
    Observations,
    Parameters,
    Statistics,
    expectation,
    initial_posterior,
)
from trustroute.analysis.study_directory import load_study, study_inputs
from trustroute.core import defaults
from trustroute.core.dataset import ROADS_FILE, check_allowed
from trustroute.core.errors import InputError
from trustroute.core.fields import OneOf, check_value
from trustroute.core.output_files import atomic_write_text
from trustroute.core.progress import bar_disable
from trustroute.core.ranges import ITERATIONS
from trustroute.participants.driver_model import (
    DEFAULT_REPORT_ACCURACY,
    PERFORMANCES,
    DriverModel,
    driver_model_from_dict,
    report_matrix,
)

MIN_ROW_WEIGHT = 5.0  # expected visits below which a T row keeps its starting value
EM_TOLERANCE = 1e-7  # stop when the mean log-likelihood per road improves less than this
# Takeover probabilities are MAP estimates under a Beta prior of this many pseudo-visits, centred
# on the incident's pooled rate (takeovers + 1) / (visits + 2): a trust level the data hardly
# visits gets its incident's rate, not 0 or 1 (unregularised EM gave 5e-123), and a probability
# is never exactly 0 or 1 unless the incident is never taken over at all (a structural zero).
TAKEOVER_PRIOR_VISITS = 2.0


def observations_from_roads(roads: pd.DataFrame, model: DriverModel,
                            source: str = ROADS_FILE) -> Observations:
    """The observable part of a roads table (incident, takeover, performance, reported trust);
    `source`, the table's file, is named in errors."""
    check_allowed(roads["incident"], model.incident_types, source, "incident",
                  f"an incident type of the driver model ({', '.join(model.incident_types)})",
                  "fit with a driver model covering the town's incidents")
    roads = roads.sort_values(["episode_id", "index"], kind="stable")
    ids, starts, lengths = np.unique(roads["episode_id"].to_numpy(), return_index=True, return_counts=True)
    n, width = ids.size, int(lengths.max()) if ids.size else 1
    row = np.repeat(np.arange(n), lengths)
    col = np.arange(len(roads)) - np.repeat(starts, lengths)
    incident_of = {name: i for i, name in enumerate(model.incident_types)}
    level_of = np.full(max(model.trust_levels) + 2, -1, dtype=np.int64)
    level_of[list(model.trust_levels)] = np.arange(model.n_trust)
    reported = roads["reported_trust"].to_numpy(dtype=np.int64, na_value=-1)  # -1 here: no report
    reported = np.where(reported >= 0, level_of[np.clip(reported, 0, level_of.size - 1)], -1)
    shape = (n, width)
    incident = np.zeros(shape, dtype=np.int64)
    takeover = np.zeros(shape, dtype=np.int64)
    performance = np.zeros(shape, dtype=np.int64)
    report = np.full(shape, -1, dtype=np.int64)
    present = np.zeros(shape, dtype=bool)
    incident[row, col] = roads["incident"].map(incident_of).to_numpy()
    takeover[row, col] = roads["takeover"].fillna(False).to_numpy(dtype=np.int64)  # null: the start road
    performance[row, col] = (roads["performance"].to_numpy() == "fail").astype(np.int64)
    report[row, col] = reported
    present[row, col] = True
    # Step t (1..L) is column t of the padded rows; column 0 is the start road (no observation).
    return Observations(
        incident=incident[:, 1:],
        takeover=takeover[:, 1:],
        performance=performance[:, 1:],
        report=report,
        mask=present[:, 1:],
        episode_ids=tuple(str(e) for e in ids),
        source=source,
    )


def starting_parameters(n_incidents: int, k: int, observations: Observations) -> Parameters:
    """A generic start, not the truth: uniform π, banded T (0.5 stay, the rest to neighbours),
    takeover 0.5 where takeovers occur (0 on incidents never taken over), accuracy 0.7."""
    band = np.zeros((k, k))
    for i in range(k):
        for j in range(k):
            band[i, j] = {0: 4.0, 1: 2.0, 2: 1.0}.get(abs(i - j), 0.1)
    band /= band.sum(axis=1, keepdims=True)
    takeover = np.full((n_incidents, k), 0.5)
    failure = np.zeros((n_incidents, k))
    for i in range(n_incidents):
        on = observations.mask & (observations.incident == i)
        if not observations.takeover[on].any():
            takeover[i] = 0.0
        if observations.performance[on].any():
            failure[i] = 0.2
    transition = np.broadcast_to(band, (n_incidents, 2, 2, k, k)).copy()
    return Parameters(
        initial=np.full(k, 1.0 / k), takeover=takeover, failure=failure, transition=transition, accuracy=0.7
    )


def fit_accuracy(report_counts: np.ndarray, k: int) -> float:
    """argmax_a Σ counts log R_a (grid then a local refinement; concave in a on [0, 1])."""

    def scores(accuracies: np.ndarray) -> np.ndarray:
        R = report_matrix(accuracies, k)
        with np.errstate(divide="ignore"):
            logs = np.where(report_counts > 0, np.log(np.maximum(R, 1e-300)), 0.0)
        return (report_counts * logs).sum(axis=(1, 2))

    grid = np.linspace(0.0, 1.0, 201)
    best = grid[int(np.argmax(scores(grid)))]
    fine = np.linspace(max(0.0, best - 0.005), min(1.0, best + 0.005), 101)
    return float(fine[int(np.argmax(scores(fine)))])


def regularised_takeover(taken: np.ndarray, visits: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """MAP takeover probabilities [I, k] (see TAKEOVER_PRIOR_VISITS); structural zeros stay zero."""
    pooled = (taken.sum(axis=1, keepdims=True) + 1.0) / (visits.sum(axis=1, keepdims=True) + 2.0)
    out = (taken + TAKEOVER_PRIOR_VISITS * pooled) / (visits + TAKEOVER_PRIOR_VISITS)
    out[previous == 0] = 0.0  # an incident never taken over: no takeover model to fit
    return out


def maximisation(stats: Statistics, previous: Parameters, fixed_accuracy: float | None) -> Parameters:
    k = previous.initial.size
    transition = previous.transition.copy()
    totals = stats.transition.sum(axis=-1)
    enough = totals >= MIN_ROW_WEIGHT
    transition[enough] = stats.transition[enough] / totals[enough][:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        failure = np.where(stats.visits > 0, stats.failure_num / stats.visits, previous.failure)
    takeover = regularised_takeover(stats.takeover_num, stats.visits, previous.takeover)
    failure[previous.failure == 0] = 0.0
    accuracy = fixed_accuracy if fixed_accuracy is not None else fit_accuracy(stats.report, k)
    initial = stats.initial / stats.initial.sum()
    return Parameters(
        initial=initial, takeover=takeover, failure=failure, transition=transition, accuracy=accuracy
    )


@dataclass
class FitResult:
    method: str
    template: DriverModel
    parameters: Parameters
    episodes: int
    transitions: int
    iterations: int
    loglik: float
    row_weight: np.ndarray  # [I, 2, 2, k] expected visits of each T row
    report_accuracy: float | None
    source: str = ""
    history: list[float] = field(default_factory=list)
    converged: bool = True  # EM: stopped by EM_TOLERANCE, not by the iteration cap
    takeover_weight: np.ndarray | None = None  # [I, k] expected visits behind each takeover probability

    @property
    def performance_dependent(self) -> bool:
        return bool(self.parameters.failure.any())

    def model_dict(self) -> dict:
        """The fitted model in the driver-model file format (validated on write)."""
        p, model = self.parameters, self.template
        accuracy = "n/a" if self.report_accuracy is None else f"{self.report_accuracy:.4f}"
        transitions: dict = {}
        for i, incident in enumerate(model.incident_types):
            transitions[incident] = {}
            for h, action in enumerate(("standstill", "takeover")):
                if self.performance_dependent:
                    transitions[incident][action] = {
                        perf: _rows(p.transition[i, h, e]) for e, perf in enumerate(PERFORMANCES)
                    }
                else:
                    transitions[incident][action] = _rows(p.transition[i, h, 0])
        out = {
            "trust_levels": list(model.trust_levels),
            "incident_types": list(model.incident_types),
            "takeover_probability": {
                inc: p.takeover[i].tolist() for i, inc in enumerate(model.incident_types)
            },
            "trust_transition": transitions,
            "trust_free_takeover_probability": dict(model.trust_free_takeover_probability),
            "initial_belief": _rows(p.initial[None, :])[0],
            "source": f"fitted by trustroute fit ({self.method}) from {self.source}: "
            f"{self.episodes} episodes, {self.transitions} roads; report accuracy {accuracy}",
        }
        if self.performance_dependent:
            out["failure_probability"] = {
                inc: p.failure[i].tolist() for i, inc in enumerate(model.incident_types)
            }
        if not model.trust_free_takeover_probability:
            del out["trust_free_takeover_probability"]   # an empty table is a table without its entries
        return out

    def model(self) -> DriverModel:
        return driver_model_from_dict(self.model_dict(), "fitted model")

    def write(self, path: Path) -> Path:
        self.model()  # validates
        return atomic_write_text(Path(path), json.dumps(self.model_dict(), indent=1), "driver model file",
                                 "pass a writable path with --out")

    def sparse_rows(self) -> list[str]:
        names = []
        for i, h, e, theta in zip(*np.nonzero(self.row_weight < MIN_ROW_WEIGHT), strict=True):
            if e == 1 and not self.performance_dependent:
                continue
            names.append(
                f"{self.template.incident_types[i]}/{('standstill', 'takeover')[h]}/"
                f"{PERFORMANCES[e]}/trust {self.template.trust_levels[theta]}"
            )
        return names

    def summary(self) -> dict:
        return {
            "method": self.method,
            "episodes": self.episodes,
            "roads": self.transitions,
            "iterations": self.iterations,
            "loglik": self.loglik,
            "report_accuracy": self.report_accuracy,
            "rows_kept_at_start_value": len(self.sparse_rows()),
            "converged": self.converged,
            "unidentified_rows": self.sparse_rows(),
            "unidentified_takeover": self.sparse_takeover(),
        }

    def sparse_takeover(self) -> list[str]:
        """Takeover probabilities resting on fewer than MIN_ROW_WEIGHT expected visits (their value
        is mostly the prior: the incident's pooled rate)."""
        if self.takeover_weight is None:
            return []
        return [
            f"{self.template.incident_types[i]}/trust {self.template.trust_levels[theta]}"
            for i, theta in zip(*np.nonzero(self.takeover_weight < MIN_ROW_WEIGHT), strict=True)
            if self.parameters.takeover[i].any()
        ]


def _rows(matrix: np.ndarray) -> list[list[float]]:
    """Rows renormalised in float64 so the file passes the 1e-9 row-sum check."""
    m = np.clip(np.asarray(matrix, dtype=float), 0.0, 1.0)
    m = m / m.sum(axis=1, keepdims=True)
    return m.tolist()


def fit_em(
    obs: Observations,
    template: DriverModel,
    iterations: int = defaults.FIT_ITERATIONS,
    fixed_accuracy: float | None = None,
    start: Parameters | None = None,
    progress: bool = False,
) -> FitResult:
    params = (
        start
        if start is not None
        else starting_parameters(len(template.incident_types), template.n_trust, obs)
    )
    if fixed_accuracy is not None:
        params.accuracy = fixed_accuracy
    history: list[float] = []
    stats = expectation(obs, params)
    converged = False
    from tqdm import tqdm

    with tqdm(total=iterations, desc="fitting (EM)", unit="iteration", disable=bar_disable(progress),
              leave=False, dynamic_ncols=True) as bar:
        for _ in range(iterations):
            params = maximisation(stats, params, fixed_accuracy)
            stats = expectation(obs, params)
            history.append(stats.loglik)
            bar.update(1)
            bar.set_postfix_str(f"loglik {stats.loglik:.1f}", refresh=False)
            if len(history) > 1 and (history[-1] - history[-2]) < EM_TOLERANCE * max(1, obs.steps):
                converged = True
                break
    return FitResult(
        method="em",
        template=template,
        parameters=params,
        episodes=obs.episodes,
        transitions=obs.steps,
        iterations=len(history),
        loglik=stats.loglik,
        row_weight=stats.transition.sum(axis=-1),
        report_accuracy=params.accuracy,
        history=history,
        converged=converged,
        takeover_weight=stats.visits,
    )


def fit_counts(obs: Observations, template: DriverModel) -> FitResult:
    """Exact reports on every road: count transitions r_{t-1} -> r_t and takeovers at r_{t-1}."""
    if ((obs.report[:, 1:] < 0) & obs.mask).any():
        raise InputError(
            obs.source,
            "reported_trust",
            "some roads carry no trust report",
            "fit with --method em (reports every N roads or noisy reports)",
        )
    k, n_inc = template.n_trust, len(template.incident_types)
    params = starting_parameters(n_inc, k, obs)
    counts = np.zeros_like(params.transition)
    visits = np.zeros_like(params.takeover)
    take = np.zeros_like(params.takeover)
    fail = np.zeros_like(params.failure)
    both = obs.mask[:, 1:]  # steps t >= 2: the trust before the road was reported at t-1
    before = obs.report[:, 1:-1][both]
    after = obs.report[:, 2:][both]
    inc, h, e = (a[:, 1:][both] for a in (obs.incident, obs.takeover, obs.performance))
    np.add.at(counts, (inc, h, e, before, after), 1.0)
    np.add.at(visits, (inc, before), 1.0)
    np.add.at(take, (inc, before), h.astype(float))
    np.add.at(fail, (inc, before), e.astype(float))
    totals = counts.sum(axis=-1)
    enough = totals >= MIN_ROW_WEIGHT
    params.transition[enough] = counts[enough] / totals[enough][:, None]
    params.takeover = regularised_takeover(take, visits, params.takeover)
    with np.errstate(invalid="ignore", divide="ignore"):
        params.failure = np.where(visits > 0, fail / visits, params.failure)
    params.accuracy = 1.0
    # θ_0 is never reported: fit π alone by EM with the counted model held fixed.
    for _ in range(30):
        initial, loglik = initial_posterior(obs, params)
        params.initial = initial / initial.sum()
    return FitResult(
        method="counts",
        template=template,
        parameters=params,
        episodes=obs.episodes,
        transitions=obs.steps,
        iterations=0,
        loglik=loglik,
        row_weight=totals,
        report_accuracy=1.0,
        takeover_weight=visits,
    )


def fit_roads(
    roads: pd.DataFrame, template: DriverModel, method: str = "em", iterations: int = defaults.FIT_ITERATIONS,
    progress: bool = False, source: str = ROADS_FILE,
) -> FitResult:
    obs = observations_from_roads(roads, template, source)
    if obs.steps == 0:
        raise InputError(
            obs.source, "", "no roads driven in the logs", "run a study with episodes first"
        )
    if method == "counts":
        return fit_counts(obs, template)
    if method == "em":
        return fit_em(obs, template, iterations, progress=progress)
    raise ValueError(f"unknown fitting method {method!r}")


FIT_METHODS = OneOf(choices=defaults.FIT_METHODS, noun="fitting method")


def fit_study(
    study_dir: Path, method: str = defaults.FIT_METHOD, iterations: int = defaults.FIT_ITERATIONS,
    progress: bool = False
) -> FitResult:
    """Fit a driver model to the consolidated logs of a study directory (`method` and `iterations`
    as `trustroute fit` takes them)."""
    check_value(method, FIT_METHODS, "--method", "")
    iterations = ITERATIONS.check(iterations)
    manifest, _, roads = load_study(Path(study_dir))
    _, template, _ = study_inputs(manifest, study_dir)
    config = manifest.get("config", {})
    if method == "auto":
        accuracy = (config.get("population") or {}).get("report_accuracy", DEFAULT_REPORT_ACCURACY)
        method = "counts" if accuracy == 1 and config.get("report_every", 1) == 1 else "em"
    result = fit_roads(roads, template, method, iterations, progress, str(Path(study_dir) / ROADS_FILE))
    result.source = str(study_dir)
    return result


def bootstrap_fit(
    roads: pd.DataFrame,
    episodes: pd.DataFrame,
    template: DriverModel,
    method: str,
    iterations: int,
    resamples: int,
    rng: np.random.Generator,
    progress=None,
) -> dict:
    """Uncertainty by resampling participants with replacement (all their episodes together) and
    refitting: 2.5/97.5 percentiles of every takeover probability and of every trust row's expected
    change E[θ' - θ] (standstill/takeover, AV success), and how many refits converged."""
    levels = np.asarray(template.trust_levels, dtype=float)
    takeovers, changes, converged = [], [], 0
    for result in bootstrap_refits(roads, episodes, template, method, iterations, resamples, rng):
        converged += bool(result.converged)
        takeovers.append(result.parameters.takeover)
        changes.append(result.parameters.transition[:, :, 0] @ levels - levels)  # [I, 2, k]
        if progress is not None:
            progress()
    takeover = np.stack(takeovers)
    change = np.stack(changes)
    names = template.incident_types
    return {
        "resamples": resamples,
        "unit": "participant",
        "converged": converged,
        "takeover_probability": {
            name: {
                "low": np.percentile(takeover[:, i], 2.5, axis=0).tolist(),
                "high": np.percentile(takeover[:, i], 97.5, axis=0).tolist(),
            }
            for i, name in enumerate(names)
        },
        "expected_trust_change": {
            f"{name}/{action}": {
                "low": np.percentile(change[:, i, h], 2.5, axis=0).tolist(),
                "high": np.percentile(change[:, i, h], 97.5, axis=0).tolist(),
            }
            for i, name in enumerate(names)
            for h, action in enumerate(("standstill", "takeover"))
        },
    }


def bootstrap_refits(roads: pd.DataFrame, episodes: pd.DataFrame, template: DriverModel, method: str,
                     iterations: int, resamples: int, rng: np.random.Generator) -> Iterator[FitResult]:
    """`resamples` refits, each on the participants drawn with replacement from `rng` (all of a
    drawn participant's episodes together, a participant drawn twice counted twice): the fits
    `bootstrap_fit` summarises and `trustroute plan --pilot` simulates with."""
    by_participant = {p: list(g["episode_id"]) for p, g in episodes.groupby("participant")}
    participants = sorted(by_participant)
    grouped = {e: g for e, g in roads.groupby("episode_id")}
    for _ in range(resamples):
        drawn = rng.choice(len(participants), size=len(participants), replace=True)
        parts = []
        for copy, index in enumerate(drawn):
            for episode_id in by_participant[participants[index]]:
                parts.append(grouped[episode_id].assign(episode_id=f"{episode_id}#{copy}"))
        yield fit_roads(pd.concat(parts, ignore_index=True), template, method, iterations)
