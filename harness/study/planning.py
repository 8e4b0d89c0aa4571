"""Simulated studies in memory, for `trustroute plan`: many whole studies of one size on the model
engine, with no part files, returning each participant's outcomes per (spec, condition).

A study config gives the cells (specs x conditions), the AV's policies (synthesized once, from the
policy cache, by the study's context) and its filter; the participants are drawn from a
`ParticipantModel`: the config's own driver model (every participant nominal), another true
driver model (`driver`), a population of driver types (`types` with weights, one type per
participant for all its episodes), or the refits of a pilot's fitted model (one drawn per
simulated study for all its participants: the fit's uncertainty is common to a study's
participants). Each cell is one `simulate_batch` call over every participant of every simulated
study, with the drivers' trust reports drawn (every `report_every` roads), so a participant's
outcome in a cell is (satisfied, mean reported trust) as the consolidated dataset
has them. The model engine has no order or carry-over effects: a participant's episodes are
independent given its driver model, so the Williams square only rounds the sample size
(`planned_participants`). The analysis of the simulated studies is analysis/study/power.py's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from trustroute.core.defaults import MAX_PARTICIPANTS
from trustroute.core.errors import InputError
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import BatchResult, simulate_batch
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.context import StudyContext
from trustroute.harness.study.latin_square import williams_rows
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.driver_types import trust_marginal
from trustroute.policies.belief.observed import observed_beliefs, reported_beliefs
from trustroute.policies.logic.trace import evaluate_traces
from trustroute.policies.model.trust_pomdp import build_pomdp


@dataclass(frozen=True, eq=False)
class ParticipantModel:
    """Who the simulated participants are: `types` (driver models) drawn with `weights`, one per
    participant (a population); one type with weight 1 is a single driver model. `per_study`: one
    type drawn per simulated study for all its participants instead (the refits of a fitted model:
    its uncertainty is shared by every participant of a study). `report_accuracy`: the accuracy of
    the participants' reports (None: the config's)."""

    label: str
    types: tuple[DriverModel, ...]
    weights: tuple[float, ...]
    per_study: bool = False
    report_accuracy: float | None = None


@dataclass(frozen=True, eq=False)
class SimulatedStudies:
    """`studies` simulated studies of `participants` participants: per study, participant, spec
    and condition (axes in that order) whether the episode satisfied its spec, and the mean
    reported trust (NaN when no report was given)."""

    participants: int
    specs: tuple[str, ...]
    conditions: tuple[str, ...]
    satisfied: np.ndarray   # bool [studies, participants, specs, conditions]
    reported: np.ndarray    # float [studies, participants, specs, conditions]
    models: np.ndarray | None = None   # int [studies]: the type each study drew (`per_study`), else None

    @property
    def studies(self) -> int:
        return int(self.satisfied.shape[0])


def planned_participants(requested: int, cells: int) -> int:
    """The smallest sample size >= `requested` that uses every row of the Williams design of
    `cells` cells equally often (harness/study/latin_square.py)."""
    rows = len(williams_rows(cells))
    return -(-max(1, requested) // rows) * rows


def participant_sizes(spec: str, cells: int) -> list[int]:
    """The sample sizes of `--participants`: "N", "A:B" or "A:B:STEP" (inclusive), each rounded up
    to a multiple of the Williams design's rows, without repeats; InputError otherwise."""
    try:
        numbers = [int(part) for part in spec.split(":")]
    except ValueError:
        numbers = []
    if not 1 <= len(numbers) <= 3 or any(n < 1 for n in numbers):
        raise InputError("--participants", spec, "not a size or a range of sizes",
                         "pass e.g. 24, 8:60 or 8:60:4 (from:to:step, participants >= 1)")
    low, high = numbers[0], numbers[1] if len(numbers) > 1 else numbers[0]
    step = numbers[2] if len(numbers) > 2 else max(1, len(williams_rows(cells)))
    if high > MAX_PARTICIPANTS:
        raise InputError("--participants", spec, "more participants than a study can have (at most "
                         f"{MAX_PARTICIPANTS})", f"pass sizes of at most {MAX_PARTICIPANTS} participants")
    if high < low:
        raise InputError("--participants", spec, f"the range ends ({high}) before it starts ({low})",
                         "pass from:to with from <= to, e.g. 8:60:4")
    return list(dict.fromkeys(planned_participants(n, cells) for n in range(low, high + 1, step)))


def simulate_studies(context: StudyContext, participants: int, studies: int, rng: np.random.Generator,
                     model: ParticipantModel | None = None, source: str = "true") -> SimulatedStudies:
    """`studies` studies of `participants` participants of the study whose context is `context`, on
    the model engine, drawn from `rng` (module docstring). model: the participants (default: the
    config's driver model); source: the belief source satisfaction is judged on (`source_satisfied`)."""

    config = context.config
    total = studies * participants
    accuracy, drawn = config.report_accuracy, None
    if model is None:
        drivers, index = [context.nominal], np.zeros(total, dtype=np.int64)
    else:
        weights = np.cumsum(np.asarray(model.weights, dtype=float))
        drivers = list(model.types)
        draws = rng.random(studies) if model.per_study else rng.random(total)
        index = np.minimum(np.searchsorted(weights / weights[-1], draws, side="right"),
                           len(drivers) - 1).astype(np.int64)
        if model.per_study:
            drawn = index
            index = np.repeat(index, participants)   # studies x participants, study-major
        if model.report_accuracy is not None:
            accuracy = model.report_accuracy
    specs, conditions = tuple(config.spec_names), tuple(config.condition_names)
    satisfied = np.zeros((studies, participants, len(specs), len(conditions)), dtype=bool)
    reported = np.full(satisfied.shape, np.nan)
    for s, spec in enumerate(specs):
        for c, condition in enumerate(conditions):
            setup = context.setup(spec, condition)
            own = is_own_verdict(source, context, setup, drivers)
            result = simulate_batch(setup, context.policies[(spec, condition)], total, rng, drivers=drivers,
                                    driver_index=index, report_accuracy=accuracy, trace=not own)
            judged = (result.satisfied if own else
                      source_satisfied(source, context, (spec, condition), setup, result, (drivers, index)))
            satisfied[:, :, s, c] = judged.reshape(studies, participants)
            reported[:, :, s, c] = np.asarray(result.mean_reported).reshape(studies, participants)
    return SimulatedStudies(participants=participants, specs=specs, conditions=conditions,
                            satisfied=satisfied, reported=reported, models=drawn)


def check_plannable(config: StudyConfig) -> None:
    """Planning simulates on the model engine the AV of the config: InputError for what it cannot."""
    if config.population is not None or config.driver_population is not None:
        raise InputError(config.source_path, "population",
                         "plan draws its participants from --driver, --population or --pilot, not from "
                         "the config's [population] or [drivers]",
                         "remove them from the config you plan with and pass --driver, --population "
                         "or --pilot")


def source_satisfied(source: str, context: StudyContext, cell: tuple[str, str], setup: EpisodeSetup,
                     result: BatchResult, drivers: tuple[Sequence[DriverModel], np.ndarray]) -> np.ndarray:
    """bool [n]: whether each episode of `result` (a traced `simulate_batch` of the (spec, condition)
    `cell` with its `setup`) satisfied the spec on the belief `source`, as the study's analysis
    judges a logged episode (docs/study.md, its item on satisfaction from the logs), where the AV's
    own verdict (`result.satisfied`) is not that judgement (`is_own_verdict`, which the caller asks
    once, before it simulates, to know whether to trace): "true" each episode's driver's exact
    filter (`drivers`: the true models and each episode's index in them); "reference" the study's one
    filter for every condition (StudyContext.reference_filter; plan refuses a config's [drivers]);
    "reported" a point mass on the last report. The spec as written (belief atoms over trust) is
    read on the trust marginals."""
    trace = result.trace
    assert trace is not None, "simulate_batch(..., trace=True) gives the trace"
    av, town = setup.driver_model, context.town
    shape = (*trace.roads.shape, context.nominal.n_trust)
    if source == "reported":
        initial = np.broadcast_to(trust_marginal(av, av.initial_belief), shape)
        beliefs = reported_beliefs(initial, trace.reports, context.nominal.trust_levels)
    else:
        models, index = (drivers if source == "true"
                         else ([context.reference_filter], np.zeros(shape[0], dtype=np.int64)))
        beliefs = np.zeros(shape)
        for k in np.unique(index).tolist():
            rows = np.flatnonzero(index == k)
            model = models[k]
            ours = np.array([model.incident_index(name) for name in av.incident_types])   # AV's -> model's
            incident = ours[trace.incident[rows]]
            beliefs[rows] = observed_beliefs(build_pomdp(town, model), incident, trace.takeover[rows],
                                             trace.performance[rows])
    return evaluate_traces(context.specs[cell[0]], town, trace.roads, beliefs, trace.lengths).satisfied


def is_own_verdict(source: str, context: StudyContext, setup: EpisodeSetup,
                   drivers: Sequence[DriverModel]) -> bool:
    """Whether `source` judges the cell's episodes as the AV itself did: "filter", or a source whose
    every judging model is the AV's own filter model with the Bayes rule (the same filter on the
    same observations: the participants are the config's driver model), so no trace is needed."""
    if source == "filter":
        return True
    if source == "reported" or setup.belief_rule != "bayes":
        return False
    models = drivers if source == "true" else [context.reference_filter]
    return all(model is setup.driver_model for model in models)

