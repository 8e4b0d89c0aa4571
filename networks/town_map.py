"""What a map of a town needs beside its roads' courses (networks/road_lookup.py, `road_shape`): the
town's extent and a length that scales markers, line widths and label offsets to the town's size,
so that a town of 12 junctions and a city of hundreds are both readable. The Rerun map
(harness/simulation/rerun_log.py) and the report's route map (analysis/study/plots.py) use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trustroute.networks.road_lookup import road_shape
from trustroute.networks.town import Town

# A marker of one unit is a 1/UNITS_ACROSS part of the map's diagonal, within these bounds (metres):
# on Town01 (395 m by 329 m with its outer streets) a unit is 3.4 m, on the 1.9 km by 1.5 km DRT net
# of the eclipse-sumo wheel 16 m.
UNITS_ACROSS = 150.0
MIN_UNIT = 1.0
MAX_UNIT = 25.0
# Above this many junctions the map names only the junctions a spec uses (names are hover text).
MAX_NAMED_JUNCTIONS = 30


@dataclass(frozen=True)
class MapFrame:
    """The bounding box of a town's junctions and road shapes, and its marker unit (metres)."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float
    unit: float

    @property
    def diagonal(self) -> float:
        return math.hypot(self.x_max - self.x_min, self.y_max - self.y_min)


def map_frame(town: Town) -> MapFrame:
    points = list(town.junctions.values())
    points += [p for road in town.geometry for p in road_shape(town, road)]
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    diagonal = math.hypot(max(xs) - min(xs), max(ys) - min(ys))
    unit = min(MAX_UNIT, max(MIN_UNIT, diagonal / UNITS_ACROSS))
    return MapFrame(x_min=min(xs), y_min=min(ys), x_max=max(xs), y_max=max(ys), unit=unit)


def names_every_junction(town: Town) -> bool:
    """Whether a map shows every junction's name (small towns) or only those a spec uses."""
    return len(town.junctions) <= MAX_NAMED_JUNCTIONS


def point_along(shape, fraction: float = 0.5, offset: float = 0.0) -> tuple[float, float]:
    """The point `fraction` of the way along a polyline (a sequence of (x, y)), moved `offset`
    metres to its right (the driving side of a directed road, in a y-up frame)."""
    points = [(float(p[0]), float(p[1])) for p in shape]
    segments = [(a, b, math.dist(a, b)) for a, b in zip(points, points[1:], strict=False)]
    segments = [s for s in segments if s[2] > 0] or [(points[0], points[-1], 0.0)]
    remaining = fraction * sum(s[2] for s in segments)
    for k, (a, b, step) in enumerate(segments):
        if remaining <= step or k == len(segments) - 1:
            if step == 0:
                return a
            t = min(1.0, max(0.0, remaining / step))
            dx, dy = (b[0] - a[0]) / step, (b[1] - a[1]) / step
            return a[0] + t * step * dx + offset * dy, a[1] + t * step * dy - offset * dx
        remaining -= step
    return points[0]
