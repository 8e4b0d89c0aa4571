"""Takeover actuation: switch the ego between autopilot and manual (human) control in SUMO.

Manual control is the human's own driving style applied to the ego vehicle: its speed factor
(a driver who has just taken control drives below the limit, 0.85), headway tau (1.8 s, in the
1.5-2 s range of human car following, against the AV's 1 s), comfortable deceleration (3 m/s²,
gentler than the AV's 4.5) and lane-change behaviour (no speed-gain changes; SUMO's overtaking
of a blocking obstacle through the oncoming lane stays possible), shown in red. The reasons are
in docs/scenes.md ("Manual driving"); they are modelling choices, not fitted values.
`hand_back` restores the autopilot values. Both keep SUMO's safe speed mode (31).

A person driving by hand (live studies) also sets the speed (`set_speed`: their pedals) and
decides when to pass an obstacle through the oncoming lane (`allow_oncoming_pass`: SUMO's
opposite-direction overtaking, off until they pull out; SUMO then pulls out when the gap allows
and back in once past the obstacle).
"""

from __future__ import annotations

from dataclasses import dataclass

SAFE_SPEED_MODE = 31


@dataclass(frozen=True)
class DrivingStyle:
    name: str                 # "auto" or "manual": the kinematics table's mode column
    speed_factor: float
    tau: float                # seconds of headway
    decel: float              # m/s²
    lane_change_mode: int
    color: tuple[int, int, int, int]


AUTOPILOT = DrivingStyle("auto", speed_factor=1.0, tau=1.0, decel=4.5, lane_change_mode=0b011001010101,
                         color=(255, 255, 255, 255))
MANUAL = DrivingStyle("manual", speed_factor=0.85, tau=1.8, decel=3.0, lane_change_mode=0b011000000101,
                      color=(230, 40, 40, 255))


def apply_style(sumo, vehicle_id: str, style: DrivingStyle) -> None:
    sumo.vehicle.setSpeedFactor(vehicle_id, style.speed_factor)
    sumo.vehicle.setTau(vehicle_id, style.tau)
    sumo.vehicle.setDecel(vehicle_id, style.decel)
    sumo.vehicle.setLaneChangeMode(vehicle_id, style.lane_change_mode)
    sumo.vehicle.setSpeedMode(vehicle_id, SAFE_SPEED_MODE)
    sumo.vehicle.setColor(vehicle_id, style.color)


def take_over(sumo, vehicle_id: str) -> str:
    """The human takes control; returns the new mode name."""
    apply_style(sumo, vehicle_id, MANUAL)
    return MANUAL.name


def hand_back(sumo, vehicle_id: str) -> str:
    """Back to autopilot (before the next junction); returns the new mode name."""
    apply_style(sumo, vehicle_id, AUTOPILOT)
    return AUTOPILOT.name


OPPOSITE_PASS_PARAMETER = "laneChangeModel.lcOpposite"   # SUMO's willingness to overtake through
                                                          # the oncoming lane: 0 never, 1 its default


def allow_oncoming_pass(sumo, vehicle_id: str, allowed: bool) -> None:
    """Whether SUMO may take the vehicle through the oncoming lane to pass what blocks it."""
    sumo.vehicle.setParameter(vehicle_id, OPPOSITE_PASS_PARAMETER, "1" if allowed else "0")


def set_speed(sumo, vehicle_id: str, speed: float | None) -> None:
    """Hold the vehicle at `speed` (m/s, at most the speed allowed on its lane; SUMO's safe speed
    mode still applies), or give the speed back to SUMO's car following (None)."""
    if speed is None:
        sumo.vehicle.setSpeed(vehicle_id, -1.0)
    else:
        allowed = sumo.vehicle.getAllowedSpeed(vehicle_id)
        sumo.vehicle.setSpeed(vehicle_id, min(max(float(speed), 0.0), allowed))
