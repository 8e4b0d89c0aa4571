"""Rerun recording of one episode (`--rrd PATH`), written from the episode's logs after the run.

It reads only these columns of the episode's logs, so scene and harness changes elsewhere leave it
working: roads (index, directed_road, action, incident, takeover, trust_after, reported_trust,
belief_after, dfa_state, sim_time_in, sim_time_out), kinematics (time, x, y, mode), incidents
(index, incident, injected_time, in_view_time, x, y, removed_time, takeover_start, takeover_end),
summary (episode_id, end_reason, sim_seconds). Reported trust may be -1 or null where none was given.

Timeline "sim_time" (a duration, seconds of SUMO time). Rerun's 2D views draw y downwards (image
rows), while SUMO nets and town files have y upwards (north): every position under world/ is logged
with y negated, so the map appears the right way up. Marker sizes and line widths are multiples of
the town's map unit (networks/town_map.py), so Town01 and a city of hundreds of junctions are both
readable; a town of more than 30 junctions shows names on hover only and draws its own lines and
markers, the incident boxes and the trail at half size (`detail`). The episode is drawn over the
town (`DRAW_ORDER`). A road is drawn along its course: the town's geometry where it has one, else
the net's lane of the edge named after it. On an imported town `net_path` is the town's own net,
the one the episode drove, so the ego's SUMO positions lie on the lanes of its roads' edges.
Entities:
- world/lanes, world/roads, world/junctions   static: every lane of the net; the town's road shapes
                                              (roads with a geometry); junction names
- world/start, world/waypoints/<atom>         static: the spec's start road and each state atom's
                                              roads, drawn wide and labelled (v1, v2, ...)
- world/incident_roads                        static: where the town places each incident kind (a
                                              marker beside the road, on its driving side)
- world/incidents/<i>_<kind>                  a labelled box from injection until removal
- world/ego/box                               oriented box (heading from successive positions), one
                                              row per SUMO step via send_columns; red when manual
- world/ego/trail                             the last TRAIL_SECONDS of positions, every TRAIL_EVERY s
- world/ego/plan                              the road being driven and the next road the policy
                                              committed to, from each decision on
- trust/true, trust/reported, trust/belief_mean   scalars (1-7) at each road's observation
- belief/p_trust_ge_6, belief/<atom>, belief/<atom>_threshold   the belief predicates of the spec
                                              (coeffs · b) and their thresholds (probability), on
                                              the logged belief over trust (a type-aware AV's
                                              trust marginal; a type-belief atom is not drawn)
- belief/distribution                         bar chart of the whole belief b(1..7)
- state/control (autopilot/manual: takeover intervals as coloured bands), state/road, state/dfa
- events                                      text log: road entered, incident in view, takeover,
                                              hand-back, trust reported, DFA state change, end

A default blueprint (`episode_blueprint`) goes into the same file: the map on the left, the trust and
belief plots, the state timeline, the belief bars and the event log on the right.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
import pandas as pd

from trustroute.harness.simulation.driving_style import MANUAL
from trustroute.networks.road_lookup import road_shape
from trustroute.networks.town_map import MapFrame, map_frame, names_every_junction, point_along

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb
    from sumolib.net import Net

    from trustroute.harness.simulation.episode_tracker import EpisodeSetup
    from trustroute.networks.town import Town

TIMELINE = "sim_time"
AUTO_COLOR = (240, 240, 240)
MANUAL_COLOR = (230, 40, 40)
PLAN_COLOR = (60, 200, 255)
START_COLOR = (80, 220, 120)
WAYPOINT_COLORS = ((255, 215, 0), (255, 120, 200), (170, 120, 255), (0, 200, 200), (255, 160, 60))
INCIDENT_COLORS = {"pedestrian": (255, 140, 0), "obstacle": (255, 200, 0), "truck": (120, 120, 255)}
# Sizes in map units (networks/town_map.py: 3.4 m on Town01, 16 m on a 2 km city): the ego box is
# drawn larger than a car (5 m) so that it stays visible, and shorter than Town01's 49 m shortest road.
EGO_LENGTH = 5.0
EGO_WIDTH = 2.4
LANE_RADIUS = 0.3
ROAD_RADIUS = 0.5
JUNCTION_RADIUS = 1.2  # 0.6 in a town whose junction names are hover text only
START_RADIUS = 1.3
WAYPOINT_RADIUS = 1.0
MARKER_RADIUS = 1.0
PLAN_RADIUS = 0.9
TRAIL_RADIUS = 0.6
OUTLINE_RADIUS = 0.4
INCIDENT_HALF_SIZE = 4.0
CITY_DETAIL = 0.5  # lanes, roads and markers of places in a town whose names are hover text only
# Layers of the map, bottom to top: the episode (plan, incidents, trail, ego) over the town.
DRAW_ORDER = {"lanes": 1.0, "roads": 2.0, "start": 3.0, "waypoints": 4.0, "incident_roads": 5.0,
              "junctions": 6.0, "plan": 7.0, "incidents": 8.0, "trail": 9.0, "ego": 10.0}
UP = np.array([1.0, -1.0])  # town and SUMO y point up, Rerun's 2D y points down
TRAIL_SECONDS = 30.0
TRAIL_POINTS = 15
TRAIL_EVERY = 2.0  # seconds of sim time between trail updates (the box moves every step)
HIGH_TRUST = 6  # the level of the P(trust >= 6) line (the paper's "hightrust")
ENTITIES = (
    "world/lanes",
    "world/roads",
    "world/junctions",
    "world/start",
    "world/incident_roads",
    "world/ego/box",
    "world/ego/trail",
    "world/ego/plan",
    "trust/true",
    "trust/reported",
    "trust/belief_mean",
    "belief/p_trust_ge_6",
    "belief/distribution",
    "state/control",
    "state/road",
    "state/dfa",
    "events",
)


class EpisodeLogs(Protocol):
    """What a recording reads of an episode's record (harness/simulation/episode.py, EpisodeRecord)."""

    @property
    def summary(self) -> Mapping[str, Any]: ...   # the summary row: values of several types

    @property
    def roads(self) -> pd.DataFrame: ...

    @property
    def kinematics(self) -> pd.DataFrame: ...

    @property
    def incidents(self) -> pd.DataFrame: ...


def _net(net_path: Path) -> Net:
    import sumolib

    return sumolib.net.readNet(str(net_path), withInternal=True, withPedestrianConnections=True)


def lane_strips(net: Net) -> list[np.ndarray]:
    """Shapes of the net's vehicle lanes, sidewalks and crossings (internal lanes left out)."""
    strips = []
    for edge in net.getEdges(withInternal=True):
        if edge.getFunction() in ("internal", "walkingarea"):
            continue
        for lane in edge.getLanes():
            strips.append(np.asarray(lane.getShape(), dtype=np.float32))
    return strips


def detail(town: Town) -> float:
    """The factor on the town's own lines and markers: 1 on a small town, CITY_DETAIL on a city
    (more than 30 junctions), where full-size lanes and markers would merge into one another and
    hide the episode; incident boxes and the ego's trail too (a city's unit is up to 25 m); the ego
    and its plan keep their size."""
    return 1.0 if names_every_junction(town) else CITY_DETAIL


def on_screen(points: np.ndarray | list) -> np.ndarray:
    """Positions (x, y) with y negated (UP): a y-up map shown the right way up in a 2D view."""
    return (np.asarray(points, dtype=np.float64).reshape(-1, 2) * UP).astype(np.float32)


def road_course(net: Net, town: Town, road: str) -> np.ndarray:
    """A directed road's course: the town's geometry where it has one (imported towns, Town01's
    outer streets), else the centre line of the vehicle lane of the net's edge named after it (the
    last lane: sidewalks come first), else the straight line between its junctions."""
    if road in town.geometry:
        return np.asarray(road_shape(town, road), dtype=np.float32)
    if net.hasEdge(road):
        return np.asarray(net.getEdge(road).getLanes()[-1].getShape(), dtype=np.float32)
    return np.asarray(road_shape(town, road), dtype=np.float32)


def _midpoint(shape: np.ndarray) -> np.ndarray:
    return np.asarray(point_along(shape, 0.5), dtype=np.float32)


def headings(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Heading (radians) at each step from the displacement since the last move (held while stopped)."""
    dx, dy = np.diff(x, prepend=x[:1]), np.diff(y, prepend=y[:1])
    moving = np.hypot(dx, dy) > 1e-3
    angle = np.arctan2(dy, dx)
    if not moving.any():
        return np.zeros_like(x)
    # Carry the last moving heading forward (and the first one back to the start).
    index = np.where(moving, np.arange(x.size), 0)
    np.maximum.accumulate(index, out=index)
    first = int(np.argmax(moving))
    index[:first] = first
    return angle[index]


def box_corners(x: np.ndarray, y: np.ndarray, heading: np.ndarray, unit: float = 3.0) -> np.ndarray:
    """[steps, 6, 2] closed outlines of the ego's box, nose forward, EGO_LENGTH by EGO_WIDTH units."""
    length, width = EGO_LENGTH * unit, EGO_WIDTH * unit
    local = np.array([[0.5, 0.5], [0.5, -0.5], [-0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]]) * [length, width]
    local = np.vstack([local[:1], [[0.75 * length, 0.0]], local[1:]])  # a pointed nose shows heading
    cos, sin = np.cos(heading)[:, None], np.sin(heading)[:, None]
    px = x[:, None] + cos * local[None, :, 0] - sin * local[None, :, 1]
    py = y[:, None] + sin * local[None, :, 0] + cos * local[None, :, 1]
    return np.stack([px, py], axis=-1).astype(np.float32)


def trail_strips(x: np.ndarray, y: np.ndarray, time: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per step, the positions of the last TRAIL_SECONDS sampled at TRAIL_POINTS: (points, lengths)."""
    step = float(np.median(np.diff(time))) if time.size > 1 else 1.0
    stride = max(1, int(round(TRAIL_SECONDS / TRAIL_POINTS / step)))
    offsets = np.arange(TRAIL_POINTS)[::-1] * stride  # oldest first
    index = np.arange(x.size)[:, None] - offsets[None, :]
    valid = index >= 0
    index = np.clip(index, 0, None)
    lengths = valid.sum(axis=1)
    points = np.stack([x[index][valid], y[index][valid]], axis=-1).astype(np.float32)
    return points, lengths


def _valid_report(value: float | None) -> bool:
    """A reported trust level was given (None, NaN and -1 mean none)."""
    return value is not None and not pd.isna(value) and int(value) >= 1


def episode_blueprint(frame: MapFrame | None = None) -> rrb.Blueprint:
    """The default layout: a large map (framed on the whole town when `frame` is given), the trust
    and belief plots, states, belief bars, events."""
    import rerun.blueprint as rrb

    # The plots and the state lanes show the whole episode, with the time cursor moving across it:
    # every sample queried (time_ranges) and the horizontal axis opened on all of them (view_range;
    # without it the viewer opens the axis on a window around the cursor's end).
    whole = rrb.VisibleTimeRange(
        TIMELINE, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
    )
    whole_axis = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                       end=rrb.TimeRangeBoundary.infinite()))
    bounds = None
    if frame is not None:  # the town with a margin of a few units, y negated as everything on the map
        margin = 4 * frame.unit
        bounds = rrb.VisualBounds2D(x_range=(frame.x_min - margin, frame.x_max + margin),
                                    y_range=(-frame.y_max - margin, -frame.y_min + margin))
    map_view = rrb.Spatial2DView(origin="world", name="map", background=(25, 25, 30), visual_bounds=bounds)
    trust_view = rrb.TimeSeriesView(
        origin="trust",
        name="trust (1-7): true, reported, belief mean",
        axis_y=rrb.ScalarAxis(range=(1.0, 7.0)),
        axis_x=whole_axis,
        time_ranges=whole,
    )
    belief_view = rrb.TimeSeriesView(
        origin="belief",
        name="belief: P(trust>=6), spec predicates, thresholds",
        contents=["+ belief/**", "- belief/distribution"],
        axis_y=rrb.ScalarAxis(range=(0.0, 1.0)),
        axis_x=whole_axis,
        time_ranges=whole,
    )
    states_view = rrb.StateTimelineView(
        origin="state", name="control (takeovers), road, DFA state", time_ranges=whole, time_view=whole_axis
    )
    bars = rrb.BarChartView(origin="belief/distribution", name="belief over trust 1..7")
    events = rrb.TextLogView(origin="events", name="events")
    return rrb.Blueprint(
        rrb.Horizontal(
            map_view,
            rrb.Vertical(
                trust_view,
                belief_view,
                states_view,
                rrb.Horizontal(bars, events, column_shares=[1, 2]),
                row_shares=[3, 3, 2, 3],
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(state="collapsed", timeline=TIMELINE),
        collapse_panels=True,
    )


def write_recording(path: Path, net_path: Path, record: EpisodeLogs, setup: EpisodeSetup) -> Path:
    """Write `record` (an EpisodeRecord of the SUMO engine) as a Rerun .rrd at `path`, with its blueprint."""
    import rerun as rr

    episode_id = str(record.summary["episode_id"])
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("trustroute", recording_id=f"trustroute-{episode_id}")
    frame = map_frame(setup.town)
    unit = frame.unit
    rec.save(str(path), default_blueprint=episode_blueprint(frame))
    net = _net(Path(net_path))
    _log_map(rec, net, setup, unit)
    _log_ego(rec, record.kinematics, unit, unit * detail(setup.town))
    _log_plan(rec, net, record.roads, setup.town, unit)
    _log_incidents(rec, record.incidents, unit * detail(setup.town))
    _log_series(rec, record.roads, setup)
    _log_events(rec, record)
    rec.flush()
    rec.disconnect()
    return path


def _log_map(rec: rr.RecordingStream, net: Net, setup: EpisodeSetup, unit: float) -> None:
    import rerun as rr

    town, spec = setup.town, setup.spec
    fine = detail(town) * unit
    rec.log("world/lanes", rr.LineStrips2D([on_screen(s) for s in lane_strips(net)], colors=(90, 90, 90),
                                           radii=LANE_RADIUS * fine, draw_order=DRAW_ORDER["lanes"]),
            static=True)
    shaped = sorted(town.geometry)
    rec.log("world/roads", rr.LineStrips2D([on_screen(road_course(net, town, r)) for r in shaped],
                                           colors=(120, 120, 130), radii=ROAD_RADIUS * fine,
                                           draw_order=DRAW_ORDER["roads"]), static=True)
    names = sorted(town.junctions)
    rec.log(
        "world/junctions",
        rr.Points2D(
            on_screen([town.junctions[n] for n in names]),
            labels=names,
            radii=JUNCTION_RADIUS * fine,
            colors=(200, 200, 200),
            show_labels=names_every_junction(town),
            draw_order=DRAW_ORDER["junctions"],
        ),
        static=True,
    )
    small = names_every_junction(town)  # a small town names roads on the map, a city on hover
    rec.log(
        "world/start",
        rr.LineStrips2D([on_screen(road_course(net, town, spec.start))], radii=START_RADIUS * unit,
                        colors=START_COLOR, labels=[f"start {spec.start}" if small else "start"],
                        show_labels=True, draw_order=DRAW_ORDER["start"]),
        static=True,
    )
    for i, (atom, roads) in enumerate(sorted(spec.state_atoms.items())):
        shapes = [road_course(net, town, road) for road in sorted(roads)]
        colour = WAYPOINT_COLORS[i % len(WAYPOINT_COLORS)]
        rec.log(f"world/waypoints/{atom}", rr.LineStrips2D([on_screen(s) for s in shapes],
                                                           radii=WAYPOINT_RADIUS * unit, colors=colour,
                                                           draw_order=DRAW_ORDER["waypoints"]),
                static=True)
        rec.log(
            f"world/waypoints/{atom}/label",
            rr.Points2D(
                on_screen([_midpoint(s) for s in shapes]),
                radii=0.5 * WAYPOINT_RADIUS * unit,
                colors=colour,
                labels=[f"{atom} ({road})" for road in sorted(roads)],
                show_labels=small,
                draw_order=DRAW_ORDER["waypoints"],
            ),
            static=True,
        )
        if not small:  # one name per waypoint set, at its first road
            rec.log(f"world/waypoints/{atom}/name",
                    rr.Points2D(on_screen([_midpoint(shapes[0])]), radii=0.5 * WAYPOINT_RADIUS * unit,
                                colors=colour, labels=[atom], show_labels=True,
                                draw_order=DRAW_ORDER["waypoints"]), static=True)
    incident_roads = sorted((road, kind) for road, kind in town.incidents.items() if kind in INCIDENT_COLORS)
    if incident_roads:
        rec.log(
            "world/incident_roads",
            rr.Points2D(
                on_screen([point_along(road_course(net, town, road), 0.5, unit)
                           for road, _ in incident_roads]),
                radii=MARKER_RADIUS * fine,
                colors=[INCIDENT_COLORS.get(k, (200, 200, 200)) for _, k in incident_roads],
                labels=[kind for _, kind in incident_roads],
                show_labels=False,
                draw_order=DRAW_ORDER["incident_roads"],
            ),
            static=True,
        )


def _log_ego(rec: rr.RecordingStream, kinematics: pd.DataFrame, unit: float, trail_unit: float) -> None:
    import rerun as rr

    time = kinematics["time"].to_numpy(dtype=float)
    if time.size == 0:
        return
    x, y = kinematics["x"].to_numpy(dtype=float), -kinematics["y"].to_numpy(dtype=float)  # on screen
    manual = kinematics["mode"].to_numpy() == MANUAL.name
    times = rr.TimeColumn(TIMELINE, duration=time)
    corners = box_corners(x, y, headings(x, y), unit)
    colours = np.where(manual[:, None], np.array(MANUAL_COLOR), np.array(AUTO_COLOR)).astype(np.uint8)
    rec.send_columns(
        "world/ego/box",
        indexes=[times],
        columns=[
            *rr.LineStrips2D.columns(strips=list(corners)),
            *rr.LineStrips2D.columns(colors=colours,
                                     radii=np.full(time.size, OUTLINE_RADIUS * unit, dtype=np.float32)),
        ],
    )
    rec.log("world/ego/box", rr.LineStrips2D.from_fields(draw_order=DRAW_ORDER["ego"]), static=True)
    points, lengths = trail_strips(x, y, time)
    trails = np.split(points, np.cumsum(lengths)[:-1])
    step = float(np.median(np.diff(time))) if time.size > 1 else 1.0
    every = np.arange(0, time.size, max(1, int(round(TRAIL_EVERY / step))))
    every = np.union1d(every, [time.size - 1])
    rec.send_columns(
        "world/ego/trail",
        indexes=[rr.TimeColumn(TIMELINE, duration=time[every])],
        columns=rr.LineStrips2D.columns(strips=[trails[i] for i in every]),
    )
    rec.log(
        "world/ego/trail",
        rr.LineStrips2D.from_fields(colors=(255, 255, 255, 150), radii=TRAIL_RADIUS * trail_unit,
                                    draw_order=DRAW_ORDER["trail"]),
        static=True,
    )
    # Control mode as a state lane: its autopilot/manual bands are the takeover intervals.
    change = np.flatnonzero(np.concatenate([[True], manual[1:] != manual[:-1]]))
    rec.send_columns(
        "state/control",
        indexes=[rr.TimeColumn(TIMELINE, duration=time[change])],
        columns=rr.StateChange.columns(state=np.where(manual[change], "manual", "autopilot")),
    )


def _log_plan(rec: rr.RecordingStream, net: Net, roads: pd.DataFrame, town: Town, unit: float) -> None:
    import rerun as rr

    for row in roads.itertuples(index=False):
        decided = float(row.sim_time_out)
        if pd.isna(row.action) or not row.action or math.isnan(decided):
            continue
        following = town.successor(row.directed_road, row.action)
        rec.set_time(TIMELINE, duration=decided)
        rec.log(
            "world/ego/plan",
            rr.LineStrips2D(
                [on_screen(road_course(net, town, row.directed_road)),
                 on_screen(road_course(net, town, following))],
                radii=PLAN_RADIUS * unit,
                colors=PLAN_COLOR,
                labels=["", f"next: {following}" if names_every_junction(town) else "next"],
                show_labels=True,
                draw_order=DRAW_ORDER["plan"],
            ),
        )


def _log_incidents(rec: rr.RecordingStream, incidents: pd.DataFrame, size: float) -> None:
    """A labelled box per placed incident, INCIDENT_HALF_SIZE by `size` (metres per unit)."""
    import rerun as rr

    for row in incidents.itertuples(index=False):
        if math.isnan(row.x) or math.isnan(row.injected_time):
            continue
        entity = f"world/incidents/{row.index}_{row.incident}"
        rec.set_time(TIMELINE, duration=float(row.injected_time))
        rec.log(
            entity,
            rr.Boxes2D(
                centers=on_screen([row.x, row.y]),
                half_sizes=[[INCIDENT_HALF_SIZE * size] * 2],
                radii=OUTLINE_RADIUS * size,
                labels=[row.incident],
                show_labels=True,
                colors=INCIDENT_COLORS.get(row.incident, (200, 200, 200)),
                draw_order=DRAW_ORDER["incidents"],
            ),
        )
        if not math.isnan(row.removed_time):
            rec.set_time(TIMELINE, duration=float(row.removed_time))
            rec.log(entity, rr.Clear(recursive=False))


def _observation_times(roads: pd.DataFrame) -> np.ndarray:
    """When each road's observation is recorded: the start road at entry, the others at their end."""
    times = roads["sim_time_out"].to_numpy(dtype=float).copy()
    entered = roads["sim_time_in"].to_numpy(dtype=float)
    times[roads["index"].to_numpy() == 0] = entered[roads["index"].to_numpy() == 0]
    return np.where(np.isnan(times), entered, times)


def marginal_coefficients(coeffs: np.ndarray, n: int) -> np.ndarray | None:
    """A belief atom's coefficients on the trust marginal of `n` levels: the atom's own, or the
    first block of one tiled over a type-aware model's types (c·marginal(b) = tile(c, K)·b,
    policies/belief/driver_types.py); None for a type-belief atom, which weighs the types apart and
    so has no value on the trust marginal the roads table logs."""
    blocks = coeffs.reshape(-1, n)
    return blocks[0] if np.all(blocks == blocks[0]) else None


def _log_series(rec: rr.RecordingStream, roads: pd.DataFrame, setup: EpisodeSetup) -> None:
    import rerun as rr

    times = _observation_times(roads)
    column = rr.TimeColumn(TIMELINE, duration=times)
    belief = np.array([np.asarray(b, dtype=float) for b in roads["belief_after"]])
    n = belief.shape[1]
    # The log holds the belief over trust: a type-aware AV's trust marginal, read with the base
    # levels (a lifted model repeats them per type) and the atoms' coefficients on the marginal
    levels = np.asarray(setup.driver_model.trust_levels, dtype=float)[:n]
    high = levels >= HIGH_TRUST
    series = {
        "trust/true": (roads["trust_after"].to_numpy(dtype=float), "true trust", (40, 40, 40)),
        "trust/belief_mean": (belief @ levels, "belief mean", (60, 200, 255)),
        "belief/p_trust_ge_6": (belief[:, high].sum(axis=1), "P(trust >= 6)", (255, 215, 0)),
    }
    for i, (name, atom) in enumerate(sorted(setup.spec.belief_atoms.items())):
        coeffs = marginal_coefficients(np.asarray(atom.coeffs, dtype=float), n)
        if coeffs is None:
            continue
        colour = WAYPOINT_COLORS[(i + 1) % len(WAYPOINT_COLORS)]
        series[f"belief/{name}"] = (belief @ coeffs, f"{name}: coeffs . b", colour)
        series[f"belief/{name}_threshold"] = (
            np.full(len(times), float(atom.offset)),
            f"{name} threshold (> {atom.offset:g})",
            (150, 150, 150),
        )
    for entity, (values, label, colour) in series.items():
        rec.log(entity, rr.SeriesLines(names=label, colors=colour, widths=2.0), static=True)
        rec.send_columns(entity, indexes=[column], columns=rr.Scalars.columns(scalars=values))
    reported = pd.to_numeric(roads["reported_trust"], errors="coerce").astype("float64").to_numpy()
    given = ~np.isnan(reported) & (reported >= 1)
    rec.log(
        "trust/reported",
        rr.SeriesPoints(names="reported trust", colors=(255, 120, 200), marker_sizes=4.0),
        static=True,
    )
    if given.any():
        rec.send_columns(
            "trust/reported",
            indexes=[rr.TimeColumn(TIMELINE, duration=times[given])],
            columns=rr.Scalars.columns(scalars=reported[given]),
        )
    for t, b in zip(times, belief, strict=True):
        rec.set_time(TIMELINE, duration=float(t))
        rec.log("belief/distribution", rr.BarChart(b))
    entered = roads["sim_time_in"].to_numpy(dtype=float)
    rec.send_columns(
        "state/road",
        indexes=[rr.TimeColumn(TIMELINE, duration=entered)],
        columns=rr.StateChange.columns(state=roads["directed_road"].astype(str).to_numpy()),
    )
    dfa = roads["dfa_state"].to_numpy()
    change = np.flatnonzero(np.concatenate([[True], dfa[1:] != dfa[:-1]]))
    rec.send_columns(
        "state/dfa",
        indexes=[rr.TimeColumn(TIMELINE, duration=times[change])],
        columns=rr.StateChange.columns(state=[f"q{int(q)}" for q in dfa[change]]),
    )


def episode_events(record: EpisodeLogs) -> list[tuple[float, str, str]]:
    """(sim time, level, text) of everything worth a line in the event log, in time order."""
    roads, incidents = record.roads, record.incidents
    times = _observation_times(roads)
    events: list[tuple[float, str, str]] = []
    previous_state = None
    for row, observed in zip(roads.itertuples(index=False), times, strict=True):
        what = f" ({row.incident})" if row.index > 0 and not pd.isna(row.incident) else " (start)"
        events.append(
            (float(row.sim_time_in), "INFO", f"road {row.index} entered: {row.directed_road}{what}")
        )
        if _valid_report(row.reported_trust):
            events.append(
                (
                    float(observed),
                    "DEBUG",
                    f"trust reported: {int(row.reported_trust)} (true {int(row.trust_after)})",
                )
            )
        if previous_state is not None and int(row.dfa_state) != previous_state:
            events.append((float(observed), "INFO", f"DFA state q{previous_state} -> q{int(row.dfa_state)}"))
        previous_state = int(row.dfa_state)
    for row in incidents.itertuples(index=False):
        if not math.isnan(row.in_view_time):
            events.append((float(row.in_view_time), "INFO", f"{row.incident} in view on road {row.index}"))
        if bool(row.takeover) and not math.isnan(row.takeover_start):
            events.append(
                (float(row.takeover_start), "WARN", f"takeover on road {row.index} ({row.incident})")
            )
            if not math.isnan(row.takeover_end):
                events.append(
                    (float(row.takeover_end), "INFO", f"hand-back to the autopilot on road {row.index}")
                )
    reason = record.summary.get("end_reason") or "unknown"
    level = "INFO" if reason == "accepted" else "WARN"
    text = "spec accepted" if reason == "accepted" else f"episode ends: {reason}"
    events.append((float(record.summary.get("sim_seconds", times[-1] if len(times) else 0.0)), level, text))
    return sorted(events, key=lambda e: e[0])


def _log_events(rec: rr.RecordingStream, record: EpisodeLogs) -> None:
    import rerun as rr

    events = episode_events(record)
    rec.send_columns(
        "events",
        indexes=[rr.TimeColumn(TIMELINE, duration=[e[0] for e in events])],
        columns=rr.TextLog.columns(text=[e[2] for e in events], level=[e[1] for e in events]),
    )
