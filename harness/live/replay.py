"""Re-drawing a live episode from its log: the person cannot be re-simulated, so `trustroute
replay` of a live study writes the episode's Rerun recording from what its part logged (the
kinematics tick by tick with the person's mode, the roads with the beliefs and stated trust, the
incidents), on the study's net, through the recording writer of simulated episodes
(harness/simulation/rerun_log.py)."""

from __future__ import annotations

from pathlib import Path

from trustroute.app.nets import net_for
from trustroute.core.dataset import part_path
from trustroute.core.errors import InputError


def draw_live_episode(study_dir: Path, episode_id: str, rrd_path: Path):
    """Write the recording of live episode `episode_id` of `study_dir` at `rrd_path`; returns the
    logged EpisodeRecord it was drawn from. InputError when the episode has no part."""
    from trustroute.harness.simulation.episode import EpisodeRecord
    from trustroute.harness.simulation.rerun_log import write_recording
    from trustroute.harness.study.context import study_context
    from trustroute.harness.study.parts import read_part
    from trustroute.harness.study.replay import find_task, study_config_from_manifest

    study_dir = Path(study_dir)
    config, _ = study_config_from_manifest(study_dir)
    task = find_task(config, episode_id, study_dir)
    path = part_path(study_dir, episode_id)
    if not path.is_file():
        raise InputError(str(study_dir), episode_id, "the episode has no part (it was not finished)",
                         "pick a finished episode (see episodes.parquet)")
    part = read_part(path)
    record = EpisodeRecord(summary=part.summary, roads=part.tables["roads"],
                           kinematics=part.tables["kinematics"], incidents=part.tables["incidents"])
    setup = study_context(config).setup(task.spec, task.condition)
    write_recording(Path(rrd_path), net_for(setup.town), record, setup)
    return record
