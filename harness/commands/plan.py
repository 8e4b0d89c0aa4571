"""`trustroute plan CONFIG`: the sample size of a study by simulation. For every size of
--participants, many whole studies of CONFIG are simulated in memory on the model engine
(harness/study/planning.py: the policies synthesized once, no part files) and each is analysed
with the report's own tests (analysis/study/power.py); the power of each test is the share of
studies in which it rejects at α. Prints a table, writes the power curve (PNG and SVG), and with
--json one object with every power, its interval, the effect's distribution and the minimal
sizes. docs/planning.md says what the simulation assumes and what it cannot tell.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click

from trustroute.harness.commands.option_groups import option, takes
from trustroute.harness.commands.options import SEED, FiniteFloat, bounded_int
from trustroute.harness.commands.output import emit, json_flag, quiet_flag, with_paths

if TYPE_CHECKING:
    from trustroute.analysis.study.power import PowerSettings

DEFAULT_OUT = Path("out") / "plan"


def participant_model(config, driver: str | None, population: str | None):
    """The simulated participants: --driver (one true driver model), --population (driver types
    with weights), or None (the config's driver model)."""
    if driver is not None and population is not None:
        from trustroute.core.errors import InputError

        raise InputError("--population", population, "--driver and --population both name the participants",
                         "pass one of them")
    from trustroute.harness.study.planning import ParticipantModel

    if driver is not None:
        from trustroute.app.inputs import driver_of

        model = driver_of(driver)
        return ParticipantModel(label=f"driver {driver}", types=(model,), weights=(1.0,))
    if population is not None:
        from trustroute.app.inputs import population_of

        types = population_of(population)
        return ParticipantModel(label=f"population {population}",
                                types=tuple(t.model for t in types.types),
                                weights=tuple(float(w) for w in types.weights))
    return None


def power_rows(table) -> list[dict]:
    """The power table as JSON rows."""
    return [{"test": p.test, "pair": list(p.pair), "spec": p.spec, "participants": p.participants,
             "studies": p.studies, "rejected": p.rejected, "power": p.power, "low": p.low, "high": p.high,
             "effect": {"median": p.effect_median, "low": p.effect_low, "high": p.effect_high}}
            for p in table]


def table_lines(table, minimal, target: float) -> list[str]:
    from trustroute.analysis.formatting import aligned_columns

    rows = [(p.test, f"{p.pair[0]} vs {p.pair[1]}", p.spec, p.participants, p.studies,
             f"{p.power:.3f} [{p.low:.3f}, {p.high:.3f}]",
             f"{p.effect_median:.3g} [{p.effect_low:.3g}, {p.effect_high:.3g}]") for p in table]
    found = [(test, f"{pair[0]} vs {pair[1]}", spec, "not reached" if n is None else str(n))
             for (test, pair, spec), n in minimal.items()]
    return [*aligned_columns(("test", "pair", "spec", "N", "studies", "power [95% CI]",
                              "effect median [2.5%, 97.5%]"), rows), "",
            *aligned_columns(("test", "pair", "spec", f"minimal N for power {target:g}"), found)]


@dataclass(frozen=True)
class PlanOptions:
    """`trustroute plan`'s options, in the order --help lists them."""

    sizes: str = option("--participants", default="8:60:4", show_default=True,
                        help="Sample sizes: N, FROM:TO or FROM:TO:STEP (each rounded up to the Williams "
                             "square).")
    simulations: int | None = option(
        "--simulations", type=bounded_int(10, 100_000), default=None,
        help="Simulated studies per size (default: until every power is within ±0.02, at most 2400).")
    tests: tuple[str, ...] = option(
        "--test", multiple=True, type=click.Choice(["mcnemar", "conditional_or", "wilcoxon", "mixed_model"]),
        help="A planned test (repeatable; default: mcnemar, conditional_or, wilcoxon).")
    alpha: float = option("--alpha", type=FiniteFloat(0.0, 0.5, open_minimum=True), default=0.05,
                          show_default=True)
    target: float = option("--target", type=FiniteFloat(0.0, 1.0, open_minimum=True), default=0.8,
                           show_default=True, help="Target power.")
    driver: str | None = option("--driver", default=None,
                                help="The participants' true driver model (default: the config's).")
    population: str | None = option("--population", default=None,
                                    help="The participants as a population of driver types.")
    seed: int = option("--seed", type=SEED, default=1, show_default=True)
    out: str | None = option("--out", type=click.Path(), default=None,
                             help="Folder of the power curve (default: out/plan/<study name>).")
    preregistration: str | None = option(
        "--preregistration", type=click.Path(), default=None,
        help="Also write a pre-registration (Markdown, OSF / AsPredicted fields) to FILE.")
    as_json: bool = json_flag()
    quiet: bool = quiet_flag()

    def power_settings(self) -> PowerSettings:
        """The power estimate's settings (the tests, alpha, the target and the simulations)."""
        from trustroute.analysis.study.power import DEFAULT_TESTS, PowerSettings

        return PowerSettings(tests=tuple(self.tests) or DEFAULT_TESTS, alpha=self.alpha, target=self.target,
                             simulations=self.simulations)


@click.command("plan")
@click.argument("config_path", metavar="CONFIG", type=click.Path())
@takes(options=PlanOptions)
def plan(config_path: str, options: PlanOptions) -> None:
    """Power and sample size of the study CONFIG, by simulating it on the model engine."""
    import numpy as np

    from trustroute.analysis.study.power import estimate_power, minimal_sizes
    from trustroute.analysis.study.power_plot import power_curve_plot
    from trustroute.harness.study.config import load_study_config
    from trustroute.harness.study.context import study_context
    from trustroute.harness.study.planning import check_plannable, participant_sizes, simulate_studies

    seed, alpha, target = options.seed, options.alpha, options.target
    started = time.perf_counter()
    config = load_study_config(config_path).with_overrides(engine="model")
    check_plannable(config)
    model = participant_model(config, options.driver, options.population)
    cells = len(config.spec_names) * len(config.condition_names)
    size_list = participant_sizes(options.sizes, cells)
    settings = options.power_settings()
    silent = options.quiet or options.as_json
    study_context(config, progress=not silent)  # every input, and the policies once, before simulating

    def simulate(participants: int, studies: int):
        # one Generator per size, so a size's studies do not depend on the other sizes tried
        rng = streams.setdefault(participants, np.random.default_rng(
            np.random.SeedSequence(seed, spawn_key=(participants,))))
        sims = simulate_studies(config, participants, studies, rng, model)
        return sims.satisfied, sims.reported, sims.specs, sims.conditions

    streams: dict[int, np.random.Generator] = {}
    echo = (lambda *_: None) if silent else (lambda size, n: click.echo(f"  N={size}: {n} studies", err=True))
    table = estimate_power(simulate, size_list, settings, echo)
    minimal = minimal_sizes(table, target)
    folder = Path(options.out) if options.out is not None else DEFAULT_OUT / config.name
    folder.mkdir(parents=True, exist_ok=True)
    who = model.label if model is not None else "the config's driver model"
    figure = power_curve_plot(table, target, alpha, folder / "power.png",
                              title=f"{config.name}: power by simulation ({who}; dashed: target {target:g}, "
                                    f"dotted: minimal N)")
    payload = {
        "study": config.name, "config_path": str(config.source_path), "config_hash": config.content_hash,
        "participants_model": who,
        "sizes": size_list, "tests": list(settings.tests), "alpha": alpha, "target": target, "seed": seed,
        "simulations": options.simulations, "precision": settings.precision,
        "power": power_rows(table),
        "minimal_participants": [{"test": t, "pair": list(p), "spec": s, "participants": n}
                                 for (t, p, s), n in minimal.items()],
        "seconds": time.perf_counter() - started,
    }
    lines = [*table_lines(table, minimal, target), f"power curve: {figure} and {figure.with_suffix('.svg')}"]
    paths = {"power_png": figure, "power_svg": figure.with_suffix(".svg")}
    if options.preregistration is not None:
        paths["preregistration"] = write_preregistration(Path(options.preregistration), payload, config)
        lines.append(f"pre-registration: {options.preregistration}")
    emit(options.as_json, with_paths(payload, paths), lines)


def write_preregistration(path: Path, payload: dict, config) -> Path:
    """The pre-registration of this plan (analysis/study/preregistration.py), written atomically."""
    from trustroute.analysis.study.preregistration import preregistration_text
    from trustroute.core.output_files import atomic_write_text
    from trustroute.harness.study.manifest import package_versions

    design = {"specs": list(config.spec_names), "conditions": list(config.condition_names),
              "seed": config.seed, "engine": config.engine, "fallback_after": config.fallback_after}
    versions = {"trustroute": package_versions().get("trustroute", "unknown"), **package_versions()}
    atomic_write_text(path, preregistration_text(payload, design, versions), "pre-registration",
                      "pass a writable --preregistration path")
    return path
