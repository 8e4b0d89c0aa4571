"""The manual-driving measures of a takeover (docs/dataset.md, incidents table), computed from what
a person's driving left: the wheel's trace and events (wheel_driving.py) and the incident's times.

- `takeover_reaction`: seconds from the incident coming into view to the takeover;
- `lateral_sd`: the standard deviation (population, ddof 0) of the lateral position during the
  takeover: the signed distance of the car's centre from its own lane's centre line, left positive
  (the field's SDLP);
- `manual_min_ttc`: the least time to collision during the takeover with a vehicle in the car's
  path (`ttc_ahead`); inf when none was closing;
- `manual_max_deceleration`: the largest deceleration (m/s², positive) between two samples;
- `oncoming_seconds`: time in the oncoming lane (from each `oncoming` event to the next event that
  leaves it);
- `road_departures`, `collisions`: the `off_road` and `collision` events during the takeover.

A trace is a list of `Sample`s in time order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

LEAVES_ONCOMING = ("own_lane", "off_road")
TTC_RANGE = 50.0     # m: vehicles farther ahead are not in the car's path for the TTC


@dataclass(frozen=True)
class Sample:
    t: float
    lateral: float        # m from its own lane's centre line, left positive
    speed: float          # m/s
    ttc: float            # s to a collision with what is in its path; inf: nothing closing


def signed_offset(shape: list[tuple[float, float]], x: float, y: float) -> float:
    """The distance of (x, y) from the polyline `shape` (a lane's centre line), left of its
    direction positive."""
    best, offset = math.inf, 0.0
    for (x0, y0), (x1, y1) in zip(shape, shape[1:], strict=False):
        dx, dy = x1 - x0, y1 - y0
        length2 = dx * dx + dy * dy
        along = 0.0 if length2 == 0.0 else min(max(((x - x0) * dx + (y - y0) * dy) / length2, 0.0), 1.0)
        px, py = x0 + along * dx, y0 + along * dy
        distance = math.hypot(x - px, y - py)
        if distance < best:
            best, offset = distance, math.copysign(distance, dx * (y - y0) - dy * (x - x0))
    return offset


def takeover_reaction(in_view_time: float, takeover_start: float) -> float:
    """NaN when either is missing (never in view, no takeover) or the takeover came first."""
    if math.isnan(in_view_time) or math.isnan(takeover_start) or takeover_start < in_view_time:
        return math.nan
    return takeover_start - in_view_time


def within(trace: list[Sample], start: float, end: float) -> list[Sample]:
    return [sample for sample in trace if start <= sample.t <= end]


def lateral_sd(trace: list[Sample]) -> float:
    if not trace:
        return math.nan
    mean = sum(sample.lateral for sample in trace) / len(trace)
    return math.sqrt(sum((sample.lateral - mean) ** 2 for sample in trace) / len(trace))


def max_deceleration(trace: list[Sample]) -> float:
    """The largest speed drop per second between consecutive samples (0 when never slowing)."""
    largest = 0.0
    for a, b in zip(trace, trace[1:], strict=False):
        if b.t > a.t:
            largest = max(largest, (a.speed - b.speed) / (b.t - a.t))
    return largest


def min_ttc(trace: list[Sample]) -> float:
    return min((sample.ttc for sample in trace), default=math.inf)


def oncoming_seconds(events: list[dict], start: float, end: float) -> float:
    """Seconds in the oncoming lane within [start, end], from the events' `oncoming` and the next
    event leaving it (still there at `end`: counted to `end`)."""
    total, entered = 0.0, None
    for event in events:
        if event["type"] == "oncoming" and entered is None:
            entered = event["t"]
        elif event["type"] in LEAVES_ONCOMING and entered is not None:
            total += max(0.0, min(event["t"], end) - max(entered, start))
            entered = None
    if entered is not None:
        total += max(0.0, end - max(entered, start))
    return total


def count(events: list[dict], kind: str, start: float, end: float) -> int:
    return sum(1 for event in events if event["type"] == kind and start <= event["t"] <= end)


def takeover_measures(trace: list[Sample], events: list[dict], start: float, end: float) -> dict:
    """The wheel's measures of the takeover from `start` to `end` (NaN `end`: to the trace's end)."""
    if math.isnan(end):
        end = trace[-1].t if trace else start
    during = within(trace, start, end)
    return {"lateral_sd": lateral_sd(during), "manual_min_ttc": min_ttc(during),
            "manual_max_deceleration": max_deceleration(during),
            "oncoming_seconds": oncoming_seconds(events, start, end),
            "road_departures": count(events, "off_road", start, end),
            "collisions": count(events, "collision", start, end)}


def ttc_ahead(x: float, y: float, angle: float, speed: float, width: float,
              others: list[tuple[float, float, float, float, float, float]]) -> float:
    """The time to collision with the nearest vehicle in the car's path: `others` as (x, y, angle,
    speed, length, width) of SUMO's front centres; in the path when its centre is ahead within
    TTC_RANGE and less than half the two widths to the side; the gap is along the heading from the
    car's front to the other's nearer end; inf when nothing there is closing."""
    heading = math.radians(angle)
    fx, fy = math.sin(heading), math.cos(heading)
    best = math.inf
    for ox, oy, other_angle, other_speed, length, other_width in others:
        other_heading = math.radians(other_angle)
        ofx, ofy = math.sin(other_heading), math.cos(other_heading)
        cx, cy = ox - ofx * length / 2, oy - ofy * length / 2   # the other's centre
        along = (cx - x) * fx + (cy - y) * fy
        side = -(cx - x) * fy + (cy - y) * fx
        if along <= 0.0 or along > TTC_RANGE or abs(side) >= (width + other_width) / 2:
            continue
        reach = abs(length / 2 * (ofx * fx + ofy * fy)) + abs(other_width / 2 * (ofx * fy - ofy * fx))
        gap = max(0.0, along - reach)
        closing = speed - other_speed * (ofx * fx + ofy * fy)
        if closing > 0.0:
            best = min(best, gap / closing)
    return best


def episode_measures(rows: list[dict]) -> dict:
    """An episode's measures over its incidents rows (dicts with the incidents table's columns):
    the mean reaction over its takeovers; over those driven by wheel (a `lateral_sd`) the mean SD
    of lateral position, the least TTC, the largest deceleration, and the sums of the time in the
    oncoming lane, the road departures and the collisions. None where nothing was measured."""
    def present(name: str, among: list[dict]) -> list:
        return [row[name] for row in among if row.get(name) is not None and not
                (isinstance(row[name], float) and math.isnan(row[name]))]

    taken = [row for row in rows if row.get("takeover")]
    reactions = present("takeover_reaction", taken)
    wheel = [row for row in taken if present("lateral_sd", [row])]
    measured = bool(wheel)
    return {
        "mean_takeover_reaction": sum(reactions) / len(reactions) if reactions else None,
        "mean_lateral_sd": (sum(present("lateral_sd", wheel)) / len(wheel)) if measured else None,
        "manual_min_ttc": min(present("manual_min_ttc", wheel), default=None),
        "manual_max_deceleration": max(present("manual_max_deceleration", wheel), default=None),
        "oncoming_seconds": sum(present("oncoming_seconds", wheel)) if measured else None,
        "road_departures": sum(present("road_departures", wheel)) if measured else None,
        "collisions": sum(present("collisions", wheel)) if measured else None,
    }
