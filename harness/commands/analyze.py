"""`trustroute analyze`: the tables of a study directory (per spec and condition, paired effects,
order effects, per driver type, the paper beside it), printed or as one JSON object (--json), and
the report rewritten; an imported real study adds its own analysis.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from trustroute.core import defaults
from trustroute.harness.commands.output import json_option, study_warnings, with_paths
from trustroute.harness.commands.study import report_paths
from trustroute.harness.study.config import BELIEF_SOURCES


@click.command("analyze")
@click.argument("study_dir", metavar="DIR", type=click.Path())
@json_option
@click.option(
    "--belief-source",
    type=click.Choice(BELIEF_SOURCES),
    default=defaults.BELIEF_SOURCE,
    help="Beliefs the spec is evaluated on: each AV's own filter, induced from reported trust, one "
    "reference filter for every condition, or each driver's true model (simulation). Default: the "
    "study config's belief_source, else the neutral one (true in simulation, reported for live and "
    "imported studies).",
)
@click.option("--wide", is_flag=True,
              help="Print the tables as wide as they are (default: fitted to 120 columns).")
@click.option(
    "--report/--no-report",
    default=None,
    help="(Re)write report.md, report.html and plots/ in DIR, or in --out (default: yes, but no with "
         "--json, which hands the analysis over as data, as the Python API's analyze does, unless "
         "--out is given; for a package, only with --out). --no-report writes nothing, --out "
         "included.",
)
@click.option("--out", type=click.Path(), default=None,
              help="Folder for the report (default: DIR); naming it asks for the report, unless "
                   "--no-report. Checked only when the report is written there, so with --no-report "
                   "it is not used. A package `trustroute export` wrote is published read-only: its "
                   "report is written only here.")
def analyze(study_dir: str, as_json: bool, belief_source: str | None, wide: bool,
            report: bool | None, out: str | None) -> None:
    """Per spec and condition of the study directory DIR, or of a package `trustroute export`
    wrote: n, satisfaction rate with CI, mean trust, paired tests."""
    from trustroute.app.analysis import analyze_study, report_wanted

    folder = None if out is None else Path(out)
    wanted = report_wanted(Path(study_dir), report,
                           defaults.REPORT_WITH_DATA if as_json else defaults.REPORT_WITH_TABLES, folder)
    warnings = study_warnings(Path(study_dir))
    result = analyze_study(Path(study_dir), belief_source, wanted, folder)
    analysis, real, paths, real_paths = result.analysis, result.real, result.report, result.written
    if as_json:
        payload = {**analysis.to_dict(), "warnings": warnings}
        if real is not None:
            payload["real_study"] = real.to_dict()
        elif result.real_note:
            payload["real_study"] = {"note": result.real_note}
        payload = with_paths(payload, {**report_paths(paths), **real_paths} if paths is not None else {})
        click.echo(json.dumps(payload, default=str))
        return
    from trustroute.analysis.formatting import TERMINAL_WIDTH
    from trustroute.analysis.study.display import format_table

    width = None if wide else TERMINAL_WIDTH
    click.echo(format_table(analysis, width))
    if real is not None:
        from trustroute.analysis.carla_study.analysis import format_real_study

        click.echo("")
        click.echo(format_real_study(real, width))
    elif result.real_note:
        click.echo(f"\nReal study: {result.real_note}.")
    if paths is not None:
        click.echo(f"report: {paths.markdown} and {paths.html}")
