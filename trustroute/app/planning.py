"""`trustroute plan`'s run, assembled once for the CLI and any script: the study config, the
simulated participants (the config's driver model, `driver`, `population` or a fitted `pilot`),
the sample sizes, the simulated studies of every size (harness/study/planning.py) analysed with
the report's tests (analysis/study/power.py), the power curve, and the JSON payload the terminal
table, `--json` and the pre-registration are read from. Defaults: trustroute/core/defaults.py.

Random streams, all from `seed`: size N's simulated studies from SeedSequence(seed,
spawn_key=(N,)), so a size's answer does not depend on the other sizes tried; the pilot's
bootstrap from SeedSequence(seed, spawn_key=(PILOT_KEY,)) (sizes are >= 1: no collision).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trustroute.analysis.belief_sources import config_belief_source
from trustroute.analysis.fitting.pilot import PilotFit, fit_pilot
from trustroute.analysis.study.power import (
    DEFAULT_TESTS,
    EFFECTS,
    Power,
    PowerSettings,
    estimate_power,
    minimal_sizes,
)
from trustroute.analysis.study.power_plot import power_curve_plot
from trustroute.analysis.study.preregistration import preregistration_text
from trustroute.app.inputs import driver_of, population_of
from trustroute.core import defaults, ranges
from trustroute.core.errors import InputError
from trustroute.core.fields import OneOf, check_value
from trustroute.core.output_files import atomic_write_text, check_output_dir
from trustroute.core.progress import bar_disable
from trustroute.harness.study.config import StudyConfig, load_study_config
from trustroute.harness.study.context import study_context
from trustroute.harness.study.manifest import package_versions
from trustroute.harness.study.planning import (
    ParticipantModel,
    check_plannable,
    participant_sizes,
    simulate_studies,
)

DEFAULT_OUT = Path("out") / "plan"
PLANNED_TEST = OneOf(choices=defaults.PLAN_TESTS, noun="test")
PILOT_KEY = 0


@dataclass(frozen=True)
class PlanSettings:
    """What a plan tries: the sample sizes (`sizes`: N, FROM:TO or FROM:TO:STEP), the simulated
    studies per size (None: until every power is within ±0.02), the tests (empty: the default
    ones), α and the target power; the participants (at most one of `driver`, `population`,
    `pilot`; none: the config's driver model), the pilot's bootstrap refits; the seed and the
    folder of the power curve (None: out/plan/<study name>)."""

    sizes: str = defaults.PLAN_PARTICIPANTS
    simulations: int | None = None
    tests: tuple[str, ...] = ()
    alpha: float = defaults.PLAN_ALPHA
    target: float = defaults.PLAN_TARGET
    driver: str | None = None
    population: str | None = None
    pilot: str | None = None
    pilot_bootstrap: int = defaults.PILOT_BOOTSTRAP
    seed: int = defaults.PLAN_SEED
    out: str | None = None

    def __post_init__(self) -> None:
        """Each number as `trustroute plan` takes it (the ranges both check, trustroute/core/ranges.py)."""
        for test in self.tests:
            check_value(test, PLANNED_TEST, "--test", "")
        ranges.keep_checked(self, {"simulations": ranges.SIMULATIONS, "alpha": ranges.ALPHA,
                                   "target": ranges.TARGET, "pilot_bootstrap": ranges.PILOT_BOOTSTRAP,
                                   "seed": ranges.SEED}, optional=("simulations",))


@dataclass(frozen=True, eq=False)
class PlanRun:
    """A finished plan: the study's config (its own engine: the plan simulated it on the model
    engine), the power table and minimal sizes, the power curve (PNG; the
    SVG beside it), the pilot's fit when there was one, and the JSON payload."""

    config: StudyConfig
    table: list[Power]
    minimal: dict
    figure: Path
    pilot: PilotFit | None
    payload: dict


def pilot_model(config: StudyConfig, settings: PlanSettings,
                progress: bool) -> tuple[ParticipantModel, PilotFit]:
    """The participants of a plan `--pilot`: the pilot's refits, one drawn per simulated study,
    reporting with the fitted accuracy (analysis/fitting/pilot.py)."""
    from tqdm import tqdm

    assert settings.pilot is not None
    rng = np.random.default_rng(np.random.SeedSequence(settings.seed, spawn_key=(PILOT_KEY,)))
    with tqdm(total=settings.pilot_bootstrap, desc="pilot bootstrap refits",
              disable=bar_disable(progress), leave=False) as bar:
        fit = fit_pilot(Path(settings.pilot), settings.pilot_bootstrap, rng, progress=bar.update,
                        expected=driver_of(config.driver_model))
    models = fit.models
    return ParticipantModel(label=fit.label(), types=models, weights=(1.0,) * len(models), per_study=True,
                            report_accuracy=fit.report_accuracy), fit


def participant_model(config: StudyConfig, settings: PlanSettings,
                      progress: bool = False) -> tuple[ParticipantModel | None, PilotFit | None]:
    """The simulated participants: --driver (one true driver model), --population (driver types
    with weights), --pilot (a fitted pilot with its uncertainty), or None (the config's model)."""
    given = [(name, value) for name, value in (("--driver", settings.driver),
             ("--population", settings.population), ("--pilot", settings.pilot)) if value is not None]
    if len(given) > 1:
        raise InputError(given[1][0], str(given[1][1]), f"{given[0][0]} and {given[1][0]} both name the "
                         "participants", "pass one of them")
    if settings.driver is not None:
        model = driver_of(settings.driver)
        return ParticipantModel(label=f"driver {settings.driver}", types=(model,), weights=(1.0,)), None
    if settings.population is not None:
        types = population_of(settings.population)
        return ParticipantModel(label=f"population {settings.population}",
                                types=tuple(t.model for t in types.types),
                                weights=tuple(float(w) for w in types.weights)), None
    if settings.pilot is not None:
        return pilot_model(config, settings, progress)
    return None, None


def plan_study(config_path: str | Path, settings: PlanSettings = PlanSettings(),
               progress: Callable[[str], object] | None = None) -> PlanRun:
    """The plan of the study config at `config_path` (module docstring). progress(line): where the
    long work reports (the CLI's stderr); None: silent."""
    started = time.perf_counter()
    study = load_study_config(config_path)   # what is registered: the study as it will run
    config = study.with_overrides(engine="model")   # what is simulated
    check_plannable(config)
    folder = check_output_dir(Path(settings.out) if settings.out is not None else DEFAULT_OUT / config.name,
                              "--out", "plan folder")   # before the simulations, not after them
    cells = len(config.spec_names) * len(config.condition_names)
    size_list = participant_sizes(settings.sizes, cells)
    power = PowerSettings(tests=tuple(settings.tests) or DEFAULT_TESTS, alpha=settings.alpha,
                          target=settings.target, simulations=settings.simulations)
    model, pilot = participant_model(config, settings, progress is not None)  # a pilot: fitted here
    context = study_context(config, progress=progress is not None)  # every input, and the policies once
    streams: dict[int, np.random.Generator] = {}
    # satisfaction is judged as the study's analysis will judge it: on its primary belief source
    source = config_belief_source(study)

    def simulate(participants: int, studies: int):
        # one Generator per size, so a size's studies do not depend on the other sizes tried
        rng = streams.setdefault(participants, np.random.default_rng(
            np.random.SeedSequence(settings.seed, spawn_key=(participants,))))
        sims = simulate_studies(context, participants, studies, rng, model, source)
        return sims.satisfied, sims.reported, sims.specs, sims.conditions, sims.models

    echo = None if progress is None else (lambda size, n: progress(f"  N={size}: {n} studies"))
    table = estimate_power(simulate, size_list, power, echo)
    minimal = minimal_sizes(table, settings.target)
    folder.mkdir(parents=True, exist_ok=True)
    who = model.label if model is not None else "the config's driver model"
    judged = f"satisfaction on beliefs from: {source}"
    title = (f"{config.name}: power by simulation ({who}; {judged}; dashed: target {settings.target:g}, "
             "dotted: minimal N, grey dotted: α)")
    if pilot is not None:
        title = (f"{config.name}: power by simulation from a pilot fit of {pilot.participants} participants "
                 f"with {len(pilot.refits)} bootstrap refits; {judged}\n(band: 95% Monte Carlo interval; "
                 f"dash-dotted: the refits' powers, 2.5-97.5%; dashed: target {settings.target:g}, dotted: "
                 "minimal N, grey dotted: α)")
    figure = power_curve_plot(table, settings.target, settings.alpha, folder / "power.png", title=title)
    payload = {
        "study": config.name, "config_path": str(config.source_path), "config_hash": study.content_hash,
        "participants_model": who, "belief_source": source,
        **({} if pilot is None else {"pilot": pilot.summary()}),
        "sizes": size_list, "tests": list(power.tests), "alpha": settings.alpha, "target": settings.target,
        "seed": settings.seed, "simulations": settings.simulations, "precision": power.precision,
        "power": power_rows(table),
        "minimal_participants": [{"test": t, "pair": list(p), "spec": s, "participants": n}
                                 for (t, p, s), n in minimal.items()],
        "seconds": time.perf_counter() - started,
    }
    return PlanRun(config=study, table=table, minimal=minimal, figure=figure, pilot=pilot, payload=payload)


def power_rows(table: list[Power]) -> list[dict]:
    """The power table as JSON rows."""
    return [{"test": p.test, "pair": list(p.pair), "spec": p.spec, "participants": p.participants,
             "studies": p.studies, "rejected": p.rejected, "power": p.power, "low": p.low, "high": p.high,
             "effect": {"measure": EFFECTS[p.test], "median": p.effect_median, "low": p.effect_low,
                        "high": p.effect_high},
             **({"over_fit": {"models": p.models, "low": p.fit_low, "high": p.fit_high}} if p.models else {})}
            for p in table]


def write_preregistration(path: Path, run: PlanRun) -> Path:
    """The pre-registration of this plan (analysis/study/preregistration.py), written atomically."""
    config = run.config
    design = {"specs": list(config.spec_names), "conditions": list(config.condition_names),
              "seed": config.seed, "engine": config.engine, "fallback_after": config.fallback_after}
    versions = {"trustroute": package_versions().get("trustroute", "unknown"), **package_versions()}
    atomic_write_text(path, preregistration_text(run.payload, design, versions), "pre-registration",
                      "pass a writable --preregistration path")
    return path
