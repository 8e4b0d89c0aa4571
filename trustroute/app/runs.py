"""Whole runs put together for the API and the CLI: one episode of a compiled problem with a
policy and a synthetic driver, and the fitting command's checks (the packaged policies driven by
fitted driver models; fitted drivers simulated on the real roads): the analysis only receives
their draws and rows."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.fitting.posterior_check import add_model, check_of, real_arrays
from trustroute.app.drivers import draw_type, episode_id, simulate, synthetic_driver
from trustroute.app.engines import check_sumo_only, engine_named
from trustroute.app.inputs import load_inputs
from trustroute.app.nets import net_for
from trustroute.app.policy import PolicySettings, policy_for
from trustroute.app.problem import check_initial_trust, compile_problem
from trustroute.core import defaults
from trustroute.core.ranges import SEED, keep_checked
from trustroute.harness.simulation.episode import EpisodeOptions, EpisodeRecord
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import simulate_batch
from trustroute.harness.simulation.sumo_start import SumoConfig
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.problem import Problem
from trustroute.policies.routing.protocol import RoutingPolicy


@dataclass(frozen=True)
class EpisodeSettings:
    """How one episode runs: the engine, the seed (SUMO's and the driver's Generator's), the
    driver's initial trust (None: drawn), and for SUMO a Rerun recording, the net (None: the
    town's, `net_for`), SUMO's options and a per-step observer."""

    engine: str = defaults.EPISODE_ENGINE
    seed: int = defaults.SEED
    initial_trust: int | None = None
    rrd: Path | None = None
    net: Path | None = None
    sumo: SumoConfig | None = None
    observer: Callable | None = None
    option: str = "--initial-trust"   # how the initial trust is named in messages

    def __post_init__(self) -> None:
        keep_checked(self, {"seed": SEED})
        # named by its fields, as the API's keywords are (the CLI's `run` always drives SUMO)
        engine = engine_named(self.engine, "EpisodeSettings", "engine", simulated=True)
        for given, what, name in ((self.rrd, "a Rerun recording", "rrd"), (self.net, "a SUMO net", "net"),
                                  (self.sumo, "a SUMO configuration", "sumo"),
                                  (self.observer, "an observer of SUMO's steps", "observer")):
            check_sumo_only(engine, given, what, "EpisodeSettings", name)


@dataclass(frozen=True)
class EpisodeRun:
    record: EpisodeRecord
    episode_id: str
    driver_type: str | None   # a population's drawn type, else None
    net: Path | None          # the SUMO net driven (None: the model engine)


def run_one_episode(problem: Problem, policy: RoutingPolicy, settings: EpisodeSettings) -> EpisodeRun:
    """One episode of `problem` with `policy`: a synthetic driver seeded by `settings.seed` (of a
    type drawn from the population first, when the problem has one), on the engine's episode
    function, with the study's rules (fallback, junction cap)."""
    engine = engine_named(settings.engine, "--engine", simulated=True)
    rng = np.random.default_rng(settings.seed)
    driver_type, model = None, problem.driver
    if problem.population is not None:
        driver_type, model = draw_type(problem.population, rng)
    check_initial_trust(model, settings.initial_trust, settings.option)
    driver = synthetic_driver(model, rng, initial_trust=settings.initial_trust)
    setup = EpisodeSetup.of(problem)
    name = episode_id(problem.spec.name, policy.name, settings.seed)
    if not engine.drives_sumo:
        return EpisodeRun(engine.run(setup, policy, driver, name, settings.seed), name, driver_type, None)
    net = settings.net if settings.net is not None else net_for(problem.town)
    sumo = settings.sumo if settings.sumo is not None else SumoConfig()
    options = EpisodeOptions(net_path=net, config=sumo, observer=settings.observer, rrd_path=settings.rrd)
    record = engine.run(setup, policy, driver, name, settings.seed, options)
    return EpisodeRun(record, name, driver_type, net)


CHECK_SPECS: tuple[str, ...] = ("phi1", "phi2")
CHECK_CONDITIONS: tuple[str, ...] = ("aware", "free")


def aware_vs_free(drivers: dict[str, DriverModel], count: int, seed: int,
                  policy_cache: Path | None = None) -> list[dict]:
    """The packaged setup's synthesized "aware" policy and the trust-free one (AV filter: the
    packaged model) driven by each named driver model in the model engine: per spec, condition and
    driver, the satisfaction rate (on the AV's belief), the mean true trust and takeovers."""
    rows: list[dict] = []
    settings = PolicySettings(cache_dir=policy_cache)
    for spec_name in CHECK_SPECS:
        problem = compile_problem(load_inputs(spec_name))
        setup = EpisodeSetup.of(problem)
        for condition in CHECK_CONDITIONS:
            policy = policy_for(problem, condition, settings)
            for name, driver in drivers.items():
                rng = np.random.default_rng([seed, len(rows)])
                frame = simulate_batch(setup, policy, count, rng, drivers=[driver]).frame()
                rows.append({
                    "spec": spec_name,
                    "condition": condition,
                    "drivers": name,
                    "episodes": count,
                    "satisfaction_rate": float(np.mean(frame["satisfied"])),
                    "mean_trust": float(np.mean(frame["mean_trust"])),
                    "takeovers_per_episode": float(np.mean(frame["takeovers"])),
                })
    return rows


def posterior_check(roads: pd.DataFrame, models: dict[str, tuple[DriverModel, float]], replicates: int,
                    rng: np.random.Generator) -> dict:
    """Real statistics, and per model (name -> (model, report accuracy)) its simulated statistics
    and distances to the real ones (analysis/fitting/posterior_check.py): `replicates` drivers of
    each model drawn on the real episodes' roads, models in order, one Generator."""
    template = next(iter(models.values()))[0]
    incident, _, _, mask = real_arrays(roads, template)
    check, _ = check_of(roads, template, replicates)
    for name, (model, accuracy) in models.items():
        drawn = simulate(model, incident, mask, accuracy, replicates, rng, template.incident_types)
        add_model(check, name, model, accuracy, incident, mask, drawn.takeover, drawn.report)
    return check
