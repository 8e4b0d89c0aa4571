"""The AV's performance on a road, measured from what happened in SUMO (docs/scenes.md).

Measures, per road, while the ego is on autopilot from the moment the road's incident is
injected until the road's observation is recorded:
- `collided`: the ego took part in a collision (SUMO's collision list);
- `max_deceleration` (m/s²): the hardest braking;
- `min_ttc` (s): the smallest time-to-collision with the leader in the ego's lane (bumper to
  bumper, when closing in);
- `min_head_on_ttc` (s): the smallest time to a head-on collision with an oncoming incident
  vehicle in the same lane (one of the two overtaking through the oncoming lane); measured
  below 3 s (`incidents.oncoming.WATCH_HORIZON`), inf when never that close;
- `min_pedestrian_distance` (m): the closest the ego's front came to the incident's person
  while the person was on the crossing;
- `time_lost` (s): the delay against free driving, the sum of (1 - v / v_free) dt.

`e = fail` when any measure crosses its limit (`PerformanceLimits`, one per incident kind,
`DEFAULT_LIMITS`; SumoConfig carries the limits an episode uses), otherwise `succ`
(the model's observation e ∈ {succ, fail}).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass


@dataclass(frozen=True)
class PerformanceLimits:
    """Where `succ` ends, for one incident kind."""

    max_deceleration: float = 5.0        # m/s²: beyond the comfortable 4.5 is an emergency brake
    min_ttc: float = 1.0                 # s, with the leader
    min_head_on_ttc: float = 1.5         # s, with an oncoming vehicle in the same lane
    min_pedestrian_distance: float = 2.0  # m: closer to a person on the crossing is a near miss
    max_time_lost: float = 60.0          # s: an AV stuck this long has not handled the scene

    def __post_init__(self) -> None:
        for name in ("max_deceleration", "min_ttc", "min_head_on_ttc", "min_pedestrian_distance",
                     "max_time_lost"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and value >= 0 and not math.isnan(value)):
                raise ValueError(f"performance limit {name} must be a number >= 0, got {value!r}")


# Per kind; the reasons are in docs/scenes.md ("Performance").
DEFAULT_LIMITS: dict[str, PerformanceLimits] = {
    "pedestrian": PerformanceLimits(max_deceleration=5.0, min_ttc=1.0, min_pedestrian_distance=2.0,
                                    max_time_lost=60.0),
    "obstacle": PerformanceLimits(max_deceleration=5.0, min_ttc=1.0, min_head_on_ttc=1.5,
                                  max_time_lost=60.0),
    "truck": PerformanceLimits(max_deceleration=5.0, min_ttc=1.0, min_head_on_ttc=1.5,
                               max_time_lost=60.0),
    "none": PerformanceLimits(),
}


def limits_for(limits: Mapping[str, PerformanceLimits], kind: str) -> PerformanceLimits:
    return limits.get(kind) or limits.get("none") or PerformanceLimits()


@dataclass
class PerformanceMonitor:
    """Accumulates the worst events of one road; `result(limits)` is "succ" or "fail"."""

    collided: bool = False
    max_deceleration: float = 0.0
    min_ttc: float = math.inf               # inf: never on a collision course within the horizon
    min_head_on_ttc: float = math.inf
    min_pedestrian_distance: float = math.inf
    time_lost: float = 0.0
    ttc_horizon: float = 1.5                # leader TTCs above this cannot matter: not computed

    def observe(self, sumo, speed: float, acceleration: float, collided: bool,
                leader: tuple[str, float] | None, min_gap: float, free_speed: float, dt: float) -> None:
        """One step. leader: (id, gap without minGap) from the ego's subscription, or None."""
        self.collided |= collided
        if -acceleration > self.max_deceleration:
            self.max_deceleration = -acceleration
        if free_speed > 0 and speed < free_speed:
            self.time_lost += (1.0 - speed / free_speed) * dt
        if leader and leader[0]:
            gap = max(leader[1] + min_gap, 0.0)   # bumper to bumper
            # TTC = gap / (speed - leader speed) >= gap / speed: only a leader this close can bring it
            # below the horizon, so its speed is asked for only then (the verdict is exact).
            if gap < speed * self.ttc_horizon:
                closing = speed - sumo.vehicle.getSpeed(leader[0])
                if closing > 0:
                    self.min_ttc = min(self.min_ttc, gap / closing)

    def head_on(self, ttc: float) -> None:
        if ttc < self.min_head_on_ttc:
            self.min_head_on_ttc = ttc

    def pedestrian_distance(self, distance: float) -> None:
        if distance < self.min_pedestrian_distance:
            self.min_pedestrian_distance = distance

    def failed_measures(self, limits: PerformanceLimits) -> list[str]:
        """Which measures crossed their limits (empty: succ)."""
        failed = []
        if self.collided:
            failed.append("collision")
        if self.max_deceleration > limits.max_deceleration:
            failed.append("deceleration")
        if self.min_ttc < limits.min_ttc:
            failed.append("ttc")
        if self.min_head_on_ttc < limits.min_head_on_ttc:
            failed.append("head_on_ttc")
        if self.min_pedestrian_distance < limits.min_pedestrian_distance:
            failed.append("pedestrian_distance")
        if self.time_lost > limits.max_time_lost:
            failed.append("time_lost")
        return failed

    def result(self, limits: PerformanceLimits | None = None) -> str:
        return verdict(self.failed_measures(limits or PerformanceLimits()))


def verdict(failed_measures: list[str]) -> str:
    """The performance e from the measures that crossed their limits: fail if any did."""
    return "fail" if failed_measures else "succ"
