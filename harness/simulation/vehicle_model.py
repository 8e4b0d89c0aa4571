"""The vehicle model a person drives by wheel and pedals (wheel_driving.py places the ego in SUMO
at its pose).

- `integrate(pose, controls, seconds, params)`: a kinematic bicycle model (speed, heading,
  position; the rear axle is the reference point, SUMO's front centre follows from it), integrated
  in sub-steps of at most 1 / MODEL_RATE seconds with the controls held over the call.
- `corners` and `overlaps`: vehicles' footprints as oriented rectangles, and whether two touch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

MODEL_RATE = 50.0            # Hz: the model's integration rate (at least 20 Hz whatever SUMO's step)


@dataclass(frozen=True)
class VehicleParams:
    wheelbase: float = 2.7         # m
    front_overhang: float = 0.9    # m from the front axle to the front bumper
    max_wheel_angle: float = 30.0  # degrees of the front wheels at full lock
    max_accel: float = 3.0         # m/s² at full throttle
    max_brake: float = 8.0         # m/s² at full brake
    rolling: float = 0.15          # m/s²: what slows a rolling car with the pedals released
    drag: float = 0.0004           # 1/m: aerodynamic drag, drag * v² in m/s²
    max_speed: float = 25.0        # m/s


@dataclass(frozen=True)
class Controls:
    """The person's inputs: steering -1 (full left) .. 1 (full right); pedals 0 .. 1."""

    steer: float = 0.0
    throttle: float = 0.0
    brake: float = 0.0

    def clamped(self) -> Controls:
        def clamp(value: float, low: float) -> float:
            return min(max(float(value), low), 1.0) if math.isfinite(value) else 0.0

        return Controls(clamp(self.steer, -1.0), clamp(self.throttle, 0.0), clamp(self.brake, 0.0))


@dataclass(frozen=True)
class Pose:
    """SUMO's view of a vehicle: front centre (x, y), angle in degrees clockwise from north, speed."""

    x: float
    y: float
    angle: float
    speed: float


def forward(angle: float) -> tuple[float, float]:
    heading = math.radians(angle)
    return math.sin(heading), math.cos(heading)


DEFAULT_PARAMS = VehicleParams()


def integrate(pose: Pose, controls: Controls, seconds: float, params: VehicleParams = DEFAULT_PARAMS) -> Pose:
    """The pose after `seconds` of the kinematic bicycle model under `controls` (no reversing)."""
    controls = controls.clamped()
    steps = max(1, math.ceil(seconds * MODEL_RATE - 1e-9))
    dt = seconds / steps
    fx, fy = forward(pose.angle)
    to_rear = params.wheelbase + params.front_overhang
    x, y = pose.x - to_rear * fx, pose.y - to_rear * fy     # the rear axle
    angle, speed = pose.angle, pose.speed
    wheel = math.tan(math.radians(controls.steer * params.max_wheel_angle))
    for _ in range(steps):
        accel = controls.throttle * params.max_accel - controls.brake * params.max_brake
        accel -= (params.rolling if speed > 0 else 0.0) + params.drag * speed * speed
        new_speed = min(max(speed + accel * dt, 0.0), params.max_speed)
        travelled = 0.5 * (speed + new_speed) * dt
        turned = math.degrees(travelled * wheel / params.wheelbase)   # right: clockwise
        fx, fy = forward(angle + turned / 2)   # along the sub-step's mean heading (second order)
        x, y = x + travelled * fx, y + travelled * fy
        angle, speed = (angle + turned) % 360.0, new_speed
    fx, fy = forward(angle)
    return Pose(x + to_rear * fx, y + to_rear * fy, angle, speed)


def corners(x: float, y: float, angle: float, length: float, width: float) -> list[tuple[float, float]]:
    """The four corners of a vehicle whose front centre is (x, y)."""
    fx, fy = forward(angle)
    lx, ly = -fy, fx
    return [(x - along * fx + side * lx, y - along * fy + side * ly)
            for along, side in ((0.0, width / 2), (0.0, -width / 2), (length, -width / 2),
                                (length, width / 2))]


def overlaps(a: list[tuple[float, float]], b: list[tuple[float, float]]) -> bool:
    """Whether two convex polygons overlap (separating axis test)."""
    for polygon in (a, b):
        for i, (x0, y0) in enumerate(polygon):
            x1, y1 = polygon[(i + 1) % len(polygon)]
            nx, ny = y0 - y1, x1 - x0
            pa = [nx * x + ny * y for x, y in a]
            pb = [nx * x + ny * y for x, y in b]
            if max(pa) < min(pb) or max(pb) < min(pa):
                return False
    return True
