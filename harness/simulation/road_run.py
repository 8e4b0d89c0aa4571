"""What happens on one road of a SUMO episode (`RoadRun`, mutable while the ego drives it), and
the incidents table the episode's roads give."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import pyarrow as pa

from trustroute.core.dataset import INCIDENTS_SCHEMA, table_from_rows
from trustroute.harness.simulation.incidents import Incident
from trustroute.harness.simulation.manual_measures import takeover_reaction
from trustroute.harness.simulation.performance import (
    PerformanceLimits,
    PerformanceMonitor,
    limits_for,
    verdict,
)


@dataclass
class RoadRun:
    """What happens on one road of the episode (mutable while the ego drives it)."""

    index: int
    road: str
    kind: str
    incident: Incident | None = None
    injected_time: float = math.nan
    time_in: float = math.nan
    in_view_time: float = math.nan
    x: float = math.nan           # where the incident object was when it came into view
    y: float = math.nan
    passed_time: float = math.nan
    removed_time: float = math.nan
    decided: bool = False
    took_over: bool = False
    takeover_start: float = math.nan
    takeover_end: float = math.nan
    committed: bool = False
    next_view_check: float = -math.inf
    # Nothing left to watch on the road: its incident removed, or decided, passed and `done`.
    quiet: bool = False
    monitor: PerformanceMonitor = field(default_factory=PerformanceMonitor)
    offsets: dict[str, float] = field(default_factory=dict)   # edge -> where it starts along the road


def incidents_table(runs: list[RoadRun], episode_id: str,
                    limits: Mapping[str, PerformanceLimits]) -> pa.Table:
    """One row per road with an incident object or a takeover (row 0, the start road, never)."""
    rows = []
    for run in runs:
        if run.index == 0 or (run.incident is None and not run.took_over):
            continue
        monitor, incident = run.monitor, run.incident
        failed = monitor.failed_measures(limits_for(limits, run.kind or "none"))
        rows.append({
            "episode_id": episode_id, "index": run.index, "directed_road": run.road,
            "incident": run.kind,
            "sumo_ids": ",".join(incident.sumo_ids) if incident is not None else None,
            # NaN is a null in these (the times and places of what never happened)
            "injected_time": run.injected_time, "in_view_time": run.in_view_time, "x": run.x, "y": run.y,
            "passed_time": run.passed_time, "removed_time": run.removed_time,
            "takeover": run.took_over, "takeover_start": run.takeover_start,
            "takeover_end": run.takeover_end,
            "performance": verdict(failed),
            "min_ttc": monitor.min_ttc, "max_deceleration": monitor.max_deceleration,
            "collided": monitor.collided, "min_head_on_ttc": monitor.min_head_on_ttc,
            "min_pedestrian_distance": monitor.min_pedestrian_distance, "time_lost": monitor.time_lost,
            "failed_measures": ",".join(failed) or None,
            "scene": incident.details() if incident is not None else None,
            "takeover_reaction": takeover_reaction(run.in_view_time, run.takeover_start),
        })
    return table_from_rows(rows, INCIDENTS_SCHEMA)
