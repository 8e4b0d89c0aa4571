"""`trustroute study`: run (or resume) a simulated within-subject study from a TOML config,
consolidate the dataset, then analyse it (tables, plots, report) unless --no-report; when episodes
failed it names them and exits 1, and writes the report only with --report-anyway.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import click

from trustroute.app.engines import SIMULATED
from trustroute.core import defaults, ranges
from trustroute.core.ranges import study_workers
from trustroute.core.wording import counted
from trustroute.harness.commands.option_groups import option, takes
from trustroute.harness.commands.options import WORKERS, Checked
from trustroute.harness.commands.output import emit, json_flag, quiet_flag, with_paths
from trustroute.harness.study.config import study_directory

if TYPE_CHECKING:   # the runner is imported when a study runs, not when the CLI starts
    from trustroute.harness.study.runner import StudyRun


def dataset_paths(study_dir: Path, manifest: dict) -> dict[str, Path]:
    """The consolidated dataset's files (manifest "files") and the manifest, by name."""
    from trustroute.core.dataset import MANIFEST_FILE

    files = {name: study_dir / file for name, file in manifest.get("files", {}).items()}
    return {**files, "manifest": study_dir / MANIFEST_FILE}


def report_paths(paths) -> dict[str, Path]:
    """The files of analysis.study.report.write_report, by name (its plots as their folder)."""
    written = {"report_markdown": paths.markdown, "report_html": paths.html}
    if paths.plots:
        written["plots"] = next(iter(paths.plots.values())).parent
    return written


def recordings_paths(study_dir: Path, record: tuple[str, ...]) -> dict[str, Path]:
    """The folder of the Rerun recordings of the config's `record` episodes, when it holds any."""
    from trustroute.harness.study.runner import recording_path

    recorded = [recording_path(study_dir, episode_id) for episode_id in record]
    return {"recordings": recorded[0].parent} if any(path.is_file() for path in recorded) else {}


@dataclass(frozen=True)
class StudyOptions:
    """`trustroute study`'s options, in the order --help lists them."""

    out: str | None = option("--out", type=click.Path(), default=None,
                             help="Study DIRECTORY (default: the config's output, else studies/<name>).")
    workers: int | None = option("--workers", type=WORKERS, default=defaults.WORKERS,
                                 help=f"Local worker processes (default: the CPU count, at most "
                                      f"{defaults.MAX_WORKERS}).")
    scheduler: str | None = option(
        "--scheduler", default=None,
        help="Dask scheduler ADDRESS, or 'local' for a local Dask cluster (default: local pool).")
    engine: str | None = option("--engine", type=click.Choice(SIMULATED), default=None,
                                help="Override the config's engine.")
    no_report: bool = option("--no-report", is_flag=True, help="Do not analyse or write the report.")
    report_anyway: bool = option(
        "--report-anyway", is_flag=True,
        help="Write the report even when some episodes failed (default: only a complete study).")
    attempts: int = option("--attempts", type=Checked(ranges.ATTEMPTS), default=defaults.ATTEMPTS,
                           show_default=True,
                           help="Runs of a failing episode at most (the first and its retries); one "
                                "that failed on its own bad input (an InputError, e.g. a jammed town) "
                                "runs once.")
    as_json: bool = json_flag()
    quiet: bool = quiet_flag()


@click.command("study")
@click.argument("config_path", metavar="CONFIG", type=click.Path())
@takes(options=StudyOptions)
@click.pass_context
def study(ctx: click.Context, config_path: str, options: StudyOptions) -> None:
    """Run (or resume) the simulated within-subject study described by CONFIG (a TOML file).

    Exit code 1 when episodes failed (they are named with their reason; a rerun runs them again, and
    one that failed on its own input, such as a jammed town, fails again), 2 for bad input."""
    from trustroute.harness.study.config import load_study_config

    config = load_study_config(config_path).with_overrides(engine=options.engine)
    workers = study_workers(options.workers)
    study_dir = study_directory(config, options.out)
    from trustroute.harness.study.runner import run_and_consolidate

    silent = options.quiet or options.as_json
    run, manifest = run_and_consolidate(config, study_dir, workers, options.scheduler, progress=not silent,
                                        echo=(lambda line: None) if silent else click.echo,
                                        attempts=options.attempts)
    from trustroute.core.dataset import EPISODES_FILE, ROADS_FILE

    paths = {**dataset_paths(run.study_dir, manifest), **recordings_paths(run.study_dir, config.record)}
    lines = [f"dataset: {run.study_dir / EPISODES_FILE}, {run.study_dir / ROADS_FILE}"]
    if run.failed:
        # On stderr, so --json keeps exactly one JSON object on stdout.
        click.echo(failed_line(run, "a rerun retries them"), err=True)
    payload = {"study_dir": str(run.study_dir), "planned": run.planned, "skipped": run.skipped,
               "ran": run.ran, "retried": run.retried, "failed": run.failed, "backend": run.backend,
               "seconds": run.seconds}
    if not options.no_report and (not run.failed or options.report_anyway):
        from trustroute.app.analysis import analyze_study

        analyzed = analyze_study(run.study_dir, None, report=True)
        analysis, written = analyzed.analysis, analyzed.report
        assert written is not None   # asked for
        paths.update(report_paths(written))
        payload["analysis"] = analysis.to_dict()
        lines += [written.table_text, f"report: {written.markdown} and {written.html}"]
    emit(options.as_json, with_paths(payload, paths), lines)
    if run.failed:
        ctx.exit(1)


def failed_line(run: StudyRun, rerun: str) -> str:
    """The error line of a run with failed episodes: how many, where their reasons are, how a rerun
    (`rerun`) retries them, and the first ten."""
    from trustroute.core.dataset import FAILURES_DIR

    more = " ..." if len(run.failed) > 10 else ""
    return (f"error: {counted(len(run.failed), 'episode')} failed (reasons in "
            f"{run.study_dir / FAILURES_DIR}; {rerun}): {', '.join(run.failed[:10])}{more}")
