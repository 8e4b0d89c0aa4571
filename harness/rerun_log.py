"""Rerun recording of one episode (`--rrd PATH`), written from the episode's logs after the run.

Entities (timeline "sim_time", a duration in seconds; the road network is static):
- world/lanes                 LineStrips2D of every vehicle lane and crossing of the net
- world/ego                   Points2D of the ego over sim time, white on autopilot, red when manual
- world/incidents/<i>_<kind>  Points2D of each incident object from injection, cleared on removal
- episode/takeover            Scalars: 1 while the driver has taken over, else 0
- episode/trust/true, episode/trust/reported, episode/belief/mean, episode/belief/p<level>,
  episode/dfa_state           Scalars at each road's end (when its observation is recorded)
- episode/roads               TextLog: the road entered and its incident

Writing after the run keeps the per-step loop free of logging. Opens in the stock `rerun` viewer.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

TIMELINE = "sim_time"
AUTO_COLOR = (255, 255, 255)
MANUAL_COLOR = (230, 40, 40)
INCIDENT_COLORS = {"pedestrian": (255, 140, 0), "obstacle": (255, 200, 0), "truck": (120, 120, 255)}


def lane_strips(net_path: Path) -> list[np.ndarray]:
    """Shapes of the net's vehicle lanes, sidewalks and crossings (internal lanes left out)."""
    import sumolib

    net = sumolib.net.readNet(str(net_path), withInternal=True, withPedestrianConnections=True)
    strips = []
    for edge in net.getEdges(withInternal=True):
        if edge.getFunction() in ("internal", "walkingarea"):
            continue
        for lane in edge.getLanes():
            strips.append(np.asarray(lane.getShape(), dtype=float))
    return strips


def write_recording(path: Path, net_path: Path, record, setup) -> Path:
    """Write `record` (an EpisodeRecord) as a Rerun .rrd at `path`."""
    import rerun as rr

    episode_id = str(record.summary["episode_id"])
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("trustroute", recording_id=f"trustroute-{episode_id}")
    rec.save(str(path))

    rec.log("world/lanes", rr.LineStrips2D(lane_strips(net_path), colors=(90, 90, 90)), static=True)
    names = [f"{name} {x:.0f},{y:.0f}" for name, (x, y) in sorted(setup.town.junctions.items())]
    rec.log("world/junctions", rr.Points2D(np.array([xy for _, xy in sorted(setup.town.junctions.items())]),
                                           labels=names, radii=4.0), static=True)

    kinematics = record.kinematics
    for t, x, y, mode in zip(kinematics["time"], kinematics["x"], kinematics["y"], kinematics["mode"],
                             strict=True):
        rec.set_time(TIMELINE, duration=float(t))
        rec.log("world/ego", rr.Points2D([[x, y]], radii=3.0,
                                         colors=MANUAL_COLOR if mode == "manual" else AUTO_COLOR))

    takeover_events: list[tuple[float, float]] = [(0.0, 0.0)]
    for row in record.incidents.itertuples(index=False):
        entity = f"world/incidents/{row.index}_{row.incident}"
        if not math.isnan(row.x):
            rec.set_time(TIMELINE, duration=float(row.injected_time))
            rec.log(entity, rr.Points2D([[row.x, row.y]], radii=4.0, labels=[row.sumo_ids],
                                        colors=INCIDENT_COLORS.get(row.incident, (200, 200, 200))))
            if not math.isnan(row.removed_time):
                rec.set_time(TIMELINE, duration=float(row.removed_time))
                rec.log(entity, rr.Clear(recursive=False))
        if row.takeover and not math.isnan(row.takeover_start):
            takeover_events.append((float(row.takeover_start), 1.0))
            end = row.takeover_end if not math.isnan(row.takeover_end) else record.summary["sim_seconds"]
            takeover_events.append((float(end), 0.0))
    for t, value in sorted(takeover_events):
        rec.set_time(TIMELINE, duration=t)
        rec.log("episode/takeover", rr.Scalars(value))

    levels = np.asarray(setup.driver_model.trust_levels, dtype=float)
    for row in record.roads.itertuples(index=False):
        entered = float(row.sim_time_in)
        rec.set_time(TIMELINE, duration=entered)
        incident = "start" if row.index == 0 else row.incident
        rec.log("episode/roads", rr.TextLog(f"{row.directed_road} ({incident})"))
        at = float(row.sim_time_out) if not math.isnan(row.sim_time_out) else entered
        rec.set_time(TIMELINE, duration=at if row.index > 0 else entered)
        belief = np.asarray(row.belief_after, dtype=float)
        rec.log("episode/trust/true", rr.Scalars(float(row.trust_after)))
        if not pd.isna(row.reported_trust):
            rec.log("episode/trust/reported", rr.Scalars(float(row.reported_trust)))
        rec.log("episode/belief/mean", rr.Scalars(float(belief @ levels)))
        for level, p in zip(setup.driver_model.trust_levels, belief, strict=True):
            rec.log(f"episode/belief/p{level}", rr.Scalars(float(p)))
        rec.log("episode/dfa_state", rr.Scalars(float(row.dfa_state)))
    rec.flush()
    rec.disconnect()
    return path
