"""The AV's performance on a road, measured from SUMO: "fail" on a collision of the ego, an
emergency braking (deceleration above `FAIL_DECELERATION`), or a time-to-collision with its
leader below `TTC_THRESHOLD`; otherwise "succ" (DESIGN.md, "Observation": e ∈ {succ, fail}).

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
LEADER_HORIZON = 100.0      # metres


@dataclass
class PerformanceMonitor:
    """Accumulates the worst events of one road; `result()` is "succ" or "fail"."""

    collided: bool = False
    max_deceleration: float = 0.0
    min_ttc: float = math.inf

    def observe(self, sumo, ego_id: str, speed: float, acceleration: float, collided: bool,
                check_leader: bool) -> None:
        self.collided |= collided
        self.max_deceleration = max(self.max_deceleration, -acceleration)
        if check_leader:
            leader = sumo.vehicle.getLeader(ego_id, LEADER_HORIZON)
            if leader and leader[0]:
                closing = speed - sumo.vehicle.getSpeed(leader[0])
                if closing > 0:
                    # getLeader's distance leaves out the ego's minGap: add it back for the real gap.
                    gap = max(leader[1] + sumo.vehicle.getMinGap(ego_id), 0.0)
                    self.min_ttc = min(self.min_ttc, gap / closing)

    def result(self) -> str:
        failed = (self.collided or self.max_deceleration > FAIL_DECELERATION
                  or self.min_ttc < TTC_THRESHOLD)
        return "fail" if failed else "succ"
