"""`trustroute replay`: re-run one episode of a finished study exactly, check it, record it; or
re-draw a live study's episode from its log (harness/live/replay.py)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from trustroute.app.engines import ENGINES
from trustroute.core.wording import counted
from trustroute.harness.commands.output import json_option, warn, with_paths

VIEWER_PORT, DATA_PORT = 9090, 9876


def rerun_command() -> str:
    """The Rerun viewer as the user types it: `rerun` when it is on PATH (or nowhere to be found),
    else the one installed beside this Python (a virtual environment not activated), by its
    absolute path: a path relative to the working directory would break on the next `cd`."""
    import shutil
    import sys

    beside = Path(sys.executable).parent / "rerun"
    if shutil.which("rerun") is not None or not beside.is_file():
        return "rerun"
    return str(beside.absolute())


def viewer_hint(rrd: Path) -> str:
    """How to open a recording: the viewer, or without a display a web viewer served on 127.0.0.1
    only (the README's form: never every interface)."""
    rerun = rerun_command()
    return (f"open it with `{rerun} {rrd}`, or on a machine without a display: `{rerun} --serve-web --bind "
            f"127.0.0.1 --web-viewer-port {VIEWER_PORT} --port {DATA_PORT} {rrd}` and browse to "
            f"http://127.0.0.1:{VIEWER_PORT}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{DATA_PORT}%2Fproxy")


@click.command("replay")
@click.argument("study_dir", metavar="STUDY_DIR", type=click.Path())
@click.argument("episode_id", metavar="EPISODE_ID")
@click.option(
    "--rrd",
    "rrd_path",
    type=click.Path(),
    default=None,
    help="Write the Rerun recording here (default: STUDY_DIR/recordings/EPISODE_ID.rrd).",
)
@click.option("--no-rrd", is_flag=True, help="Only check the replay; write no recording.")
@click.option("--gui", is_flag=True, help="Show the episode in sumo-gui (needs a display).")
@json_option
def replay(
    study_dir: str, episode_id: str, rrd_path: str | None, no_rrd: bool, gui: bool, as_json: bool
) -> None:
    """Re-run EPISODE_ID of STUDY_DIR from its seeds and population draws; fail if it differs.
    A live study's episode is re-drawn from its log instead (a person is not re-simulated)."""
    from trustroute.harness.study.replay import replay_episode, study_config_from_manifest
    from trustroute.harness.study.runner import recording_path

    config, _ = study_config_from_manifest(Path(study_dir))
    engine = ENGINES[config.engine]
    if not engine.synthetic:   # people drove it: re-drawn from its log
        draw_live(Path(study_dir), episode_id, rrd_path, no_rrd, as_json)
        return
    rrd = Path(rrd_path) if rrd_path and not no_rrd else None   # model study: an error naming the engine
    if not no_rrd and engine.records and rrd is None:
        rrd = recording_path(Path(study_dir), episode_id)
    # why no recording is written, when none is (an explicit --rrd on a model study is an error)
    no_recording = ("--no-rrd" if no_rrd else
                    f"the study ran the {config.engine} engine, which has no SUMO scene to record "
                    '(run the study with engine = "sumo" for recordings)' if rrd is None else None)
    # said on stderr before the episode runs, so even a replay that then fails says it
    result = replay_episode(Path(study_dir), episode_id, rrd_path=rrd, gui=gui,
                            warn=warn)
    roads = result.record.roads
    payload = {
        "episode_id": episode_id,
        "reproduced": True,
        "roads": len(roads),
        "route": roads["directed_road"].tolist(),
        "trust": roads["trust_after"].tolist(),
        "rrd": str(rrd) if rrd else None,
        "rrd_bytes": rrd.stat().st_size if rrd else None,
        "no_recording": no_recording,
        "warnings": list(result.warnings),
    }
    if as_json:
        click.echo(json.dumps(with_paths(payload, {"rrd": rrd})))
        return
    click.echo(
        f"{episode_id}: replay reproduces the log ({counted(len(roads), 'road')}, trust "
        f"{' '.join(str(t) for t in payload['trust'])})"
    )
    click.echo("route: " + " ".join(payload["route"]))
    if no_recording is not None and not no_rrd:
        click.echo(f"no recording written: {no_recording}")
    if rrd:
        click.echo(f"wrote {rrd} ({payload['rrd_bytes'] / 1000:.0f} kB); {viewer_hint(rrd)}")


def draw_live(study_dir: Path, episode_id: str, rrd_path: str | None, no_rrd: bool, as_json: bool) -> None:
    """The recording of a live episode, drawn from its log."""
    from trustroute.core.errors import InputError
    from trustroute.harness.live.replay import draw_live_episode
    from trustroute.harness.study.runner import recording_path

    if no_rrd:
        raise InputError("--no-rrd", "", "a live episode's replay is its recording, drawn from the log",
                         "replay it without --no-rrd")
    rrd = Path(rrd_path) if rrd_path else recording_path(study_dir, episode_id)
    record = draw_live_episode(study_dir, episode_id, rrd)
    roads = record.roads
    payload = {"episode_id": episode_id, "reproduced": False, "drawn_from_log": True, "roads": len(roads),
               "route": roads["directed_road"].tolist(), "ticks": len(record.kinematics), "rrd": str(rrd),
               "rrd_bytes": rrd.stat().st_size}
    if as_json:
        click.echo(json.dumps(with_paths(payload, {"rrd": rrd})))
        return
    click.echo(f"{episode_id}: a live episode, drawn from its log ({counted(len(roads), 'road')}, "
               f"{payload['ticks']} ticks; a person is not re-simulated)")
    click.echo("route: " + " ".join(payload["route"]))
    click.echo(f"wrote {rrd} ({payload['rrd_bytes'] / 1000:.0f} kB); {viewer_hint(rrd)}")
