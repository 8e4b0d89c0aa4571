"""`trustroute demo`: the paper-size study on the defaults, analysed, with a recording of one episode.

21 participants x (aware, free) x (φ1, φ2) = 84 episodes in SUMO (counterbalanced), then the
analysis and report, then one episode (participant 0, φ1, aware) replayed with the same seeds into
a Rerun `.rrd`. Resumable: a rerun skips finished episodes. When the SUMO engine is not installed
the demo says so and runs the model engine instead (no recording).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click

from trustroute.networks.errors import InputError

DEFAULT_OUT = Path("out") / "demo"
DEMO_STUDY = {
    "name": "demo",
    "participants": 21,
    "seed": 1,
    "specs": ["phi1", "phi2"],
    "conditions": ["aware", "free"],
}


def record_episode(config, study_dir: Path, episode_id: str) -> Path:
    """Replay one planned episode in SUMO with its seeds and write `<study>/<episode_id>.rrd`."""
    from trustroute.harness.study.plan import plan_episodes
    from trustroute.harness.study.runner import run_planned_episode

    task = next(t for t in plan_episodes(config) if t.episode_id == episode_id)
    path = Path(study_dir) / f"{episode_id}.rrd"
    if not path.exists():
        run_planned_episode(config, task, rrd_path=path)
    return path


@click.command("demo")
@click.option(
    "--out",
    "out",
    type=click.Path(),
    default=str(DEFAULT_OUT),
    show_default=True,
    help="Study directory (a rerun resumes).",
)
@click.option("--workers", type=int, default=None, help="Local worker processes (default: CPU count).")
@click.option("--engine", type=click.Choice(["sumo", "model"]), default="sumo", show_default=True)
@click.option("--participants", type=int, default=21, show_default=True)
def demo(out: str, workers: int | None, engine: str, participants: int) -> None:
    """Run the paper-size study (21 participants) on the defaults and show where the results are."""
    from trustroute.harness.study.config import study_config_from_dict
    from trustroute.harness.study.runner import run_and_consolidate

    if participants < 1:
        raise InputError("--participants", "", f"must be >= 1, got {participants}", "pass e.g. 21")
    config = study_config_from_dict(
        {"study": {**DEMO_STUDY, "participants": participants, "engine": engine}},
        "trustroute demo",
        Path.cwd(),
    )
    study_dir = Path(out)
    workers = workers if workers is not None else (os.cpu_count() or 1)
    click.echo(
        f"demo: {participants} participants x 2 specs x 2 conditions, {engine} engine, into {study_dir}"
    )
    run, _ = run_and_consolidate(config, study_dir, workers, None, echo=click.echo)
    from trustroute.analysis.report import write_report

    paths = write_report(run.study_dir)
    click.echo("")
    click.echo(paths.table_text)
    click.echo("")
    from trustroute.analysis.dataset import EPISODES_FILE, ROADS_FILE

    click.echo(f"results: {run.study_dir / EPISODES_FILE} (episodes), {run.study_dir / ROADS_FILE} (roads)")
    click.echo(f"report:  {paths.markdown}  and  {paths.html}")
    if engine == "sumo":
        episode_id = f"p{0:05d}-phi1-aware"
        try:
            rrd = record_episode(config, run.study_dir, episode_id)
            click.echo(f"episode recording: {rrd}  (open with: {_rerun_command()} {rrd})")
        except Exception as exc:  # the study is done; a failed recording must not hide it
            click.echo(f"episode recording failed: {type(exc).__name__}: {exc}")
    if run.failed:
        click.echo(f"{len(run.failed)} episodes failed: see {run.study_dir / 'failures'}")


def _rerun_command() -> str:
    """The rerun viewer installed beside this Python (e.g. .venv/bin/rerun), else plain `rerun`."""
    beside = Path(sys.executable).parent / "rerun"
    return os.path.relpath(beside) if beside.is_file() else "rerun"
