"""`trustroute import`: convert logs of real studies into study directories.

import carla-logs SOURCE --out STUDY_DIR  the CARLA study of Yu et al. (ICRA 2024): SOURCE is a
                                          checkout of shuyang-dong/trust_aware_hrc_carla_sim, a folder
                                          of its trust_level_record CSVs or one of them
                                          (docs/real_study.md)
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from trustroute.core.wording import counted
from trustroute.harness.commands.output import json_option, quiet_option, with_paths


@click.group("import")
def import_group() -> None:
    """Convert logs of real studies into study directories that `trustroute analyze` reads."""


@import_group.command("carla-logs")
@click.argument("source", metavar="SOURCE", type=click.Path())
@click.option("--out", "out", type=click.Path(), required=True, help="Study DIRECTORY to write.")
@quiet_option
@json_option
def carla_logs(source: str, out: str, quiet: bool, as_json: bool) -> None:
    """Import the authors' CARLA logs in SOURCE into the study directory --out.

    SOURCE is a checkout of their repository, a folder of their trust_level_record CSVs (searched
    recursively) or one such CSV (a study of that one episode).
    """
    from trustroute.analysis.carla_study.log_import import LOG_TRUNCATED, import_carla_logs

    manifest = import_carla_logs(Path(source), Path(out), progress=not (quiet or as_json))
    info = manifest["real_study"]
    imported = [e for e in info["inventory"] if e.get("status") == "imported"]
    summary = {
        "study_dir": str(out),
        "participants": len(info["participants"]),
        "episodes": len(imported),
        "excluded_files": len(info["inventory"]) - len(imported),
        "missing_sessions": info["missing_sessions"],
        "truncated_logs": [e["file"] for e in imported if e["log_end"] == LOG_TRUNCATED],
    }
    if as_json:
        from trustroute.harness.commands.study import dataset_paths

        click.echo(json.dumps(with_paths(summary, dataset_paths(Path(out), manifest))))
        return
    click.echo(
        f"imported {counted(summary['episodes'], 'episode')} of "
        f"{counted(summary['participants'], 'participant')} into {out}; "
        f"{counted(summary['excluded_files'], 'file')} excluded (warm-up, pilot, sample); "
        f"missing sessions: {', '.join(summary['missing_sessions']) or 'none'}"
    )
    truncated = summary["truncated_logs"]
    if truncated:
        click.echo(f"{counted(len(truncated), 'log')} truncated (the drive ended on a road before the "
                   f"route's end; log_end {LOG_TRUNCATED!r} in real_episodes.parquet): "
                   f"{', '.join(truncated)}")
