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
    help="(Re)write report.md, report.html and plots/ in DIR (default: yes, but no with --json, "
         "which hands the analysis over as data, as the Python API's analyze does).",
)
def analyze(study_dir: str, as_json: bool, belief_source: str | None, wide: bool,
            report: bool | None) -> None:
    """Per spec and condition of the study directory DIR: n, satisfaction rate with CI, mean trust,
    paired tests."""
    from trustroute.analysis.study.analysis import study_analysis
    from trustroute.core.dataset import CARLA_LOGS_ENGINE

    warnings = study_warnings(Path(study_dir))
    analysis = study_analysis(Path(study_dir), belief_source=belief_source)
    real = None
    if analysis.manifest.get("engine") == CARLA_LOGS_ENGINE:
        from trustroute.analysis.carla_study.analysis import real_study_analysis, write_real_study_report

        real = real_study_analysis(Path(study_dir))
    paths = None
    real_paths: dict[str, Path] = {}
    if report is None:
        report = defaults.REPORT_WITH_DATA if as_json else defaults.REPORT_WITH_TABLES
    if report:
        from trustroute.analysis.study.report import write_report

        paths = write_report(Path(study_dir), analysis=analysis)
        if real is not None:
            written = write_real_study_report(real, Path(study_dir))
            real_paths = {"real_study_json": written, "real_study_text": written.with_suffix(".txt")}
    if as_json:
        payload = {**analysis.to_dict(), "warnings": warnings}
        if real is not None:
            payload["real_study"] = real.to_dict()
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
    if paths is not None:
        click.echo(f"report: {paths.markdown} and {paths.html}")
