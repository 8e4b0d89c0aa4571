"""`trustroute plan CONFIG`: the sample size of a study by simulation. For every size of
--participants, many whole studies of CONFIG are simulated in memory on the model engine
(harness/study/planning.py: the policies synthesized once, no part files) and each is analysed
with the report's own tests (analysis/study/power.py); the power of each test is the share of
studies in which it rejects at α. The participants are the config's driver model, --driver,
--population, or --pilot: the driver model fitted on a pilot study with its bootstrap refits, one
drawn per simulated study (analysis/fitting/pilot.py). Prints a table, writes the power curve (PNG
and SVG), and with --json one object with every power, its interval, the effect's distribution and
the minimal sizes. The run is assembled in trustroute/app/planning.py; this command parses and
prints. docs/planning.md says what the simulation assumes and what it cannot tell.
"""

from __future__ import annotations

from pathlib import Path

import click

from trustroute.core import defaults
from trustroute.harness.commands.options import SEED, FiniteFloat, bounded_int
from trustroute.harness.commands.output import emit, json_option, quiet_option, with_paths


def table_lines(table, minimal, target: float) -> list[str]:
    from trustroute.analysis.formatting import aligned_columns

    over_fit = any(p.models for p in table)   # a pilot's refits: the power's range over them
    rows = [(p.test, f"{p.pair[0]} vs {p.pair[1]}", p.spec, p.participants, p.studies,
             f"{p.power:.3f} [{p.low:.3f}, {p.high:.3f}]",
             *([f"[{p.fit_low:.3f}, {p.fit_high:.3f}]"] if over_fit else []),
             f"{p.effect_median:.3g} [{p.effect_low:.3g}, {p.effect_high:.3g}]") for p in table]
    found = [(test, f"{pair[0]} vs {pair[1]}", spec, "not reached" if n is None else str(n))
             for (test, pair, spec), n in minimal.items()]
    return [*aligned_columns(("test", "pair", "spec", "N", "studies", "power [95% CI]",
                              *(["refits' powers [2.5%, 97.5%]"] if over_fit else []),
                              "effect median [2.5%, 97.5%]"), rows), "",
            *aligned_columns(("test", "pair", "spec", f"minimal N for power {target:g}"), found)]


def pilot_lines(pilot) -> list[str]:
    """What the participants of a --pilot plan rest on (the JSON's "pilot")."""
    if pilot is None:
        return []
    fits = 1 + len(pilot.refits)
    converged = f"; {pilot.converged} of {fits} fits converged" if pilot.method == "em" else ""
    return [f"participants: {pilot.label()}",
            f"  fitted by {pilot.method} on {pilot.episodes} episodes ({pilot.roads} roads, {pilot.reports} "
            f"trust reports); reports drawn with the fitted accuracy {pilot.report_accuracy:.3f}{converged}",
            "  power: averaged over the refits, with the Monte Carlo 95% interval of that average; the "
            "refits' powers: the range over the pilot's uncertainty (each refit's power from its own "
            "studies, so Monte Carlo noise widens it)", ""]


@click.command("plan")
@click.argument("config_path", metavar="CONFIG", type=click.Path())
@click.option("--participants", "sizes", default=defaults.PLAN_PARTICIPANTS, show_default=True,
              help="Sample sizes: N, FROM:TO or FROM:TO:STEP (each rounded up to the Williams square).")
@click.option("--simulations", type=bounded_int(10, 100_000), default=None,
              help="Simulated studies per size (default: until every power is within ±0.02, at most 2400).")
@click.option("--test", "tests", multiple=True,
              type=click.Choice(["mcnemar", "conditional_or", "wilcoxon", "mixed_model"]),
              help="A planned test (repeatable; default: mcnemar, conditional_or, wilcoxon).")
@click.option("--alpha", type=FiniteFloat(0.0, 0.5, open_minimum=True), default=defaults.PLAN_ALPHA,
              show_default=True)
@click.option("--target", "target", type=FiniteFloat(0.0, 1.0, open_minimum=True),
              default=defaults.PLAN_TARGET, show_default=True, help="Target power.")
@click.option("--driver", default=None, help="The participants' true driver model (default: the config's).")
@click.option("--population", default=None, help="The participants as a population of driver types.")
@click.option("--pilot", default=None, metavar="STUDY_DIR",
              help="The participants as the driver model fitted on this pilot study, with its uncertainty "
              "(bootstrap refits over the pilot's participants, one drawn per simulated study).")
@click.option("--pilot-bootstrap", type=bounded_int(0, 10_000), default=defaults.PILOT_BOOTSTRAP,
              show_default=True,
              help="With --pilot: bootstrap refits (0: the point fit alone, no uncertainty).")
@click.option("--seed", type=SEED, default=defaults.PLAN_SEED, show_default=True)
@click.option("--out", type=click.Path(), default=None,
              help="Folder of the power curve (default: out/plan/<study name>).")
@click.option("--preregistration", type=click.Path(), default=None,
              help="Also write a pre-registration (Markdown, OSF / AsPredicted fields) to FILE.")
@json_option
@quiet_option
def plan(config_path: str, sizes: str, simulations: int | None, tests: tuple[str, ...], alpha: float,
         target: float, driver: str | None, population: str | None, pilot: str | None, pilot_bootstrap: int,
         seed: int, out: str | None, preregistration: str | None, as_json: bool, quiet: bool) -> None:
    """Power and sample size of the study CONFIG, by simulating it on the model engine."""
    from trustroute.app.planning import PlanSettings, plan_study, write_preregistration

    settings = PlanSettings(sizes=sizes, simulations=simulations, tests=tuple(tests), alpha=alpha,
                            target=target, driver=driver, population=population, pilot=pilot,
                            pilot_bootstrap=pilot_bootstrap, seed=seed, out=out)
    progress = None if quiet or as_json else (lambda line: click.echo(line, err=True))
    run = plan_study(config_path, settings, progress)
    figure = run.figure
    lines = [*pilot_lines(run.pilot), *table_lines(run.table, run.minimal, target),
             f"power curve: {figure} and {figure.with_suffix('.svg')}"]
    paths = {"power_png": figure, "power_svg": figure.with_suffix(".svg")}
    if preregistration is not None:
        paths["preregistration"] = write_preregistration(Path(preregistration), run)
        lines.append(f"pre-registration: {preregistration}")
    emit(as_json, with_paths(run.payload, paths), lines)
