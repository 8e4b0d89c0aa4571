"""Takeover actuation: switch the ego between autopilot and manual (human) control in SUMO.

Manual control is the human's own driving style applied to the ego vehicle: its speed factor
(humans here drive a little slower than the AV), headway tau, comfortable deceleration and
lane-change behaviour (no speed-gain changes), shown in red. `hand_back` restores the autopilot
values. Both keep SUMO's safe speed mode (31), so neither mode ever drives through a pedestrian.
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
