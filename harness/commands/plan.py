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

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click

from trustroute.core import defaults, ranges
from trustroute.harness.commands.option_groups import option, takes
from trustroute.harness.commands.options import SEED, Checked
from trustroute.harness.commands.output import emit, json_flag, quiet_flag, with_paths

if TYPE_CHECKING:
    from trustroute.app.planning import PlanSettings


def table_lines(table, minimal, target: float) -> list[str]:
    from trustroute.analysis.formatting import aligned_columns
    from trustroute.analysis.study.power import EFFECTS

    over_fit = any(p.models for p in table)   # a pilot's refits: the power's range over them
    rows = [(p.test, f"{p.pair[0]} vs {p.pair[1]}", p.spec, p.participants, p.studies,
             f"{p.power:.3f} [{p.low:.3f}, {p.high:.3f}]",
             *([f"[{p.fit_low:.3f}, {p.fit_high:.3f}]"] if over_fit else []),
             EFFECTS[p.test], f"{p.effect_median:.3g} [{p.effect_low:.3g}, {p.effect_high:.3g}]")
            for p in table]
    found = [(test, f"{pair[0]} vs {pair[1]}", spec, "not reached" if n is None else str(n))
             for (test, pair, spec), n in minimal.items()]
    return [*aligned_columns(("test", "pair", "spec", "N", "studies", "power [95% CI]",
                              *(["refits' powers [2.5%, 97.5%]"] if over_fit else []),
                              "effect", "its median [2.5%, 97.5%]"), rows), "",
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


@dataclass(frozen=True)
class PlanOptions:
    """`trustroute plan`'s options, in the order --help lists them."""

    sizes: str = option("--participants", default=defaults.PLAN_PARTICIPANTS, show_default=True,
                        help="Sample sizes: N, FROM:TO or FROM:TO:STEP (each rounded up to the Williams "
                             "square).")
    simulations: int | None = option(
        "--simulations", type=Checked(ranges.SIMULATIONS), default=None,
        help="Simulated studies per size (default: until every power is within ±0.02, at most 2400).")
    tests: tuple[str, ...] = option(
        "--test", multiple=True, type=click.Choice(defaults.PLAN_TESTS),
        help=f"A planned test (repeatable; default: {', '.join(defaults.PLAN_DEFAULT_TESTS)}).")
    alpha: float = option("--alpha", type=Checked(ranges.ALPHA),
                          default=defaults.PLAN_ALPHA, show_default=True,
                          help="Significance level α of every planned test (a p-value below it, or a "
                               "(1 − α) interval excluding 1, rejects).")
    target: float = option("--target", type=Checked(ranges.TARGET),
                           default=defaults.PLAN_TARGET, show_default=True, help="Target power.")
    driver: str | None = option("--driver", default=None,
                                help="The participants' true driver model (default: the config's).")
    population: str | None = option("--population", default=None,
                                    help="The participants as a population of driver types.")
    pilot: str | None = option(
        "--pilot", default=None, metavar="STUDY_DIR",
        help="The participants as the driver model fitted on this pilot study, with its uncertainty "
             "(bootstrap refits over the pilot's participants, one drawn per simulated study).")
    pilot_bootstrap: int = option("--pilot-bootstrap", type=Checked(ranges.PILOT_BOOTSTRAP),
                                  default=defaults.PILOT_BOOTSTRAP, show_default=True,
                                  help="With --pilot: bootstrap refits (0: the point fit alone, no "
                                       "uncertainty).")
    seed: int = option("--seed", type=SEED, default=defaults.PLAN_SEED, show_default=True,
                       help="Seed of the simulated studies and the pilot's bootstrap (the same seed "
                            "gives the same table).")
    out: str | None = option("--out", type=click.Path(), default=None,
                             help="Folder of the power curve (default: out/plan/<study name>).")
    preregistration: str | None = option(
        "--preregistration", type=click.Path(), default=None,
        help="Also write a pre-registration (Markdown, OSF / AsPredicted fields) to FILE.")
    as_json: bool = json_flag()
    quiet: bool = quiet_flag()

    def settings(self) -> PlanSettings:
        """The plan's settings (trustroute/app/planning.py)."""
        from trustroute.app.planning import PlanSettings

        return PlanSettings(sizes=self.sizes, simulations=self.simulations, tests=tuple(self.tests),
                            alpha=self.alpha, target=self.target, driver=self.driver,
                            population=self.population, pilot=self.pilot,
                            pilot_bootstrap=self.pilot_bootstrap, seed=self.seed, out=self.out)


@click.command("plan")
@click.argument("config_path", metavar="CONFIG", type=click.Path())
@takes(options=PlanOptions)
def plan(config_path: str, options: PlanOptions) -> None:
    """Power and sample size of the study CONFIG, by simulating it on the model engine."""
    from trustroute.app.planning import plan_study, write_preregistration
    from trustroute.core.output_files import check_output_file

    if options.preregistration is not None:
        check_output_file(options.preregistration, "--preregistration", "pre-registration",
                          {"CONFIG": config_path, "--driver": options.driver,
                           "--population": options.population}, {"--pilot": options.pilot}, suffix=".md")
    progress = None if options.quiet or options.as_json else (lambda line: click.echo(line, err=True))
    run = plan_study(config_path, options.settings(), progress)
    figure = run.figure
    from trustroute.analysis.belief_sources import judged_on

    lines = [judged_on(run.payload["belief_source"]), *pilot_lines(run.pilot),
             *table_lines(run.table, run.minimal, options.target),
             f"power curve: {figure} and {figure.with_suffix('.svg')}"]
    paths = {"power_png": figure, "power_svg": figure.with_suffix(".svg")}
    if options.preregistration is not None:
        paths["preregistration"] = write_preregistration(Path(options.preregistration), run)
        lines.append(f"pre-registration: {options.preregistration}")
    emit(options.as_json, with_paths(run.payload, paths), lines)
