"""The AV's performance on a road, measured from SUMO: "fail" on a collision of the ego, an
emergency braking (deceleration above `FAIL_DECELERATION`), or a time-to-collision with its
leader below `TTC_THRESHOLD`; otherwise "succ" (docs/model.md, "The model": e ∈ {succ, fail}).

Only the AV's own driving counts: the runner measures while the ego is on autopilot, from the
moment the road's incident is injected until the road's observation is recorded. The leader
query (the one non-subscribed call) runs only while a vehicle incident is live, so roads without
one cost nothing per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

FAIL_DECELERATION = 5.0     # m/s²: beyond the comfortable maximum (4.5) is an emergency brake
TTC_THRESHOLD = 1.0         # seconds, on the bumper-to-bumper gap


@dataclass
class PerformanceMonitor:
    """Accumulates the worst events of one road; `result()` is "succ" or "fail"."""

    collided: bool = False
    max_deceleration: float = 0.0
    min_ttc: float = math.inf      # measured only below TTC_THRESHOLD (inf: never that close)

    def observe(self, sumo, speed: float, acceleration: float, collided: bool,
                leader: tuple[str, float] | None, min_gap: float) -> None:
        """One step. leader: (id, gap without minGap) from the ego's subscription, or None."""
        self.collided |= collided
        if -acceleration > self.max_deceleration:
            self.max_deceleration = -acceleration
        if leader and leader[0]:
            gap = max(leader[1] + min_gap, 0.0)   # bumper to bumper
            # TTC = gap / (speed - leader speed) >= gap / speed: only a leader this close can bring it
            # below the threshold, so its speed is asked for only then (the verdict is exact).
            if gap < speed * TTC_THRESHOLD:
                closing = speed - sumo.vehicle.getSpeed(leader[0])
                if closing > 0:
                    self.min_ttc = min(self.min_ttc, gap / closing)

    def result(self) -> str:
        failed = (self.collided or self.max_deceleration > FAIL_DECELERATION
                  or self.min_ttc < TTC_THRESHOLD)
        return "fail" if failed else "succ"
