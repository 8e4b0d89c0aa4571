"""`trustroute demo`: the paper-size study on the defaults, analysed, with a recording of one episode.

21 participants x (aware, free) x (φ1, φ2) = 84 episodes in SUMO (counterbalanced), then the
analysis and report, then one episode (participant 0, φ1, aware) replayed with the same seeds into
a Rerun `.rrd`. Resumable: a rerun skips finished episodes. When the SUMO engine is not installed
the demo says so and runs the model engine instead (no recording).

`--town city` runs the same on the packaged city (the RESCO Ingolstadt scenario, docs/cities.md):
its 5-waypoint spec `city5`, "aware" synthesized for 40 junctions (the fallback after 40), and the
scenario's own demand as background traffic; the recording is of `city5` instead of φ1.
"""

from __future__ import annotations

from pathlib import Path

import click

from trustroute.app.engines import ENGINES, SIMULATED
from trustroute.core import defaults, ranges
from trustroute.core.ranges import study_workers
from trustroute.core.wording import counted
from trustroute.harness.commands.options import WORKERS, Checked
from trustroute.harness.commands.output import emit, json_option, quiet_option, with_paths
from trustroute.harness.study.plan import episode_id as planned_episode_id

DEFAULT_OUT = Path("out") / "demo"
DEMO_STUDY = {
    "name": "demo",
    "participants": 21,
    "seed": 1,
    "specs": ["phi1", "phi2"],
    "conditions": ["aware", "free"],
}
# What the demo changes on another town than the default (keys of [study]).
DEMO_TOWNS: dict[str, dict] = {
    "city": {"name": "demo_city", "town": "city", "specs": ["city5"], "routes": ["city"],
             "horizon": 40, "fallback_after": 40},
}
DEFAULT_TOWN = "town01_carla"


def record_episode(context, study_dir: Path, episode_id: str) -> Path:
    """Replay one planned episode of the study whose context is `context` (the run's) in SUMO with
    its seeds and write `<study>/<episode_id>.rrd`."""
    from trustroute.harness.study.plan import plan_episodes
    from trustroute.harness.study.runner import run_planned_episode

    task = next(t for t in plan_episodes(context.config) if t.episode_id == episode_id)
    path = Path(study_dir) / f"{episode_id}.rrd"
    if not path.exists():
        run_planned_episode(context, task, rrd_path=path)
    return path


@click.command("demo")
@click.option(
    "--out",
    "out",
    type=click.Path(),
    default=str(DEFAULT_OUT),
    show_default=True,
    help="Study DIRECTORY (a rerun resumes).",
)
@click.option("--workers", type=WORKERS, default=defaults.WORKERS,
              help=f"Local worker processes (default: the CPU count, at most {defaults.MAX_WORKERS}).")
@click.option("--engine", type=click.Choice(SIMULATED), default=defaults.EPISODE_ENGINE, show_default=True,
              help="What runs the episodes: " + "; ".join(f"{name} ({ENGINES[name].description})"
                                                          for name in SIMULATED) + ".")
@click.option("--participants", type=Checked(ranges.PARTICIPANTS), default=DEMO_STUDY["participants"],
              show_default=True, help="Synthetic participants; each drives every spec in both conditions.")
@click.option("--town", type=click.Choice([DEFAULT_TOWN, *DEMO_TOWNS]), default=DEFAULT_TOWN,
              show_default=True, help="The paper's town, or the city (the RESCO Ingolstadt scenario; "
              "needs pip install 'trustroute[cities]').")
@json_option
@quiet_option
@click.pass_context
def demo(ctx: click.Context, out: str, workers: int | None, engine: str, participants: int, town: str,
         as_json: bool, quiet: bool) -> None:
    """Run the paper-size study (21 participants) on the defaults and show where the results are."""
    from trustroute.harness.commands.replay import viewer_hint
    from trustroute.harness.commands.study import dataset_paths, failed_line, report_paths
    from trustroute.harness.study.config import study_config_from_dict
    from trustroute.harness.study.runner import check_study_output, run_and_consolidate

    study = {**DEMO_STUDY, **DEMO_TOWNS.get(town, {}), "participants": participants, "engine": engine}
    config = study_config_from_dict({"study": study}, "trustroute demo", Path.cwd())
    study_dir = Path(out)
    workers = study_workers(workers)
    silent = quiet or as_json
    say = (lambda line: None) if silent else click.echo
    specs = len(study["specs"])
    on_town = "" if town == DEFAULT_TOWN else f", town {town}"
    check_study_output(study_dir)   # before the line announcing the run (the run checks it again)
    say(f"demo: {counted(participants, 'participant')} x {counted(specs, 'spec')} x 2 conditions, "
        f"{engine} engine{on_town}, into {study_dir}")
    run, manifest = run_and_consolidate(config, study_dir, workers, None, progress=not silent, echo=say)
    if run.failed:
        click.echo(failed_line(run, "rerun the demo to retry them"), err=True)
        ctx.exit(1)
    from trustroute.app.analysis import analyze_study

    analyzed = analyze_study(run.study_dir, None, report=True)
    analysis, written = analyzed.analysis, analyzed.report
    assert written is not None   # asked for
    paths = {**dataset_paths(run.study_dir, manifest), **report_paths(written)}
    lines = [
        "",
        written.table_text,
        "",
        f"results: {paths['episodes']} (episodes), {paths['roads']} (roads)",
        f"report:  {written.markdown}  and  {written.html}",
    ]
    payload = {"study_dir": str(run.study_dir), "engine": engine, "failed": run.failed,
               "analysis": analysis.to_dict()}
    if ENGINES[engine].records:
        episode_id = planned_episode_id(0, study["specs"][0], "aware")
        try:
            rrd = record_episode(run.context, run.study_dir, episode_id)
            paths["rrd"] = rrd
            lines.append(f"episode recording: {rrd}; {viewer_hint(rrd)}")
        except Exception as exc:  # the study is done; a failed recording must not hide it
            payload["recording_error"] = f"{type(exc).__name__}: {exc}"
            lines.append(f"episode recording failed: {payload['recording_error']}")
    emit(as_json, with_paths(payload, paths), lines)
