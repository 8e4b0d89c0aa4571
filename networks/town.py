"""Town files: schema, validation, directed-road states, actions, lengths, shortest paths.

A town file is JSON with `junctions` (name -> [x, y] in metres), `roads` (list of
undirected [U, V] pairs, each a two-way road unless `one_way` says otherwise) and `incidents` (one
entry per directed road "U-V": obstacle, pedestrian, truck or none); the optional keys of real
roads (one-way roads, shapes and lengths, the source SUMO net, turn restrictions) are read by
networks/road_geometry.py; every key: docs/formats/town.md.
A state of the model is a directed road "U-V": the vehicle has just arrived at V from U.
"""

from __future__ import annotations

import functools
import hashlib
import heapq
import json
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypedDict

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.fields import (
    Anything,
    Field,
    ListOf,
    Number,
    OneOf,
    Table,
    Text,
    check_fields,
    check_value,
    field_table,
    keys,
)
from trustroute.core.packaged import PackagedKind, passed_how
from trustroute.core.validation import parse_json, read_text, require_object
from trustroute.core.wording import shown_value
from trustroute.networks.road import Road
from trustroute.networks.road_geometry import (
    EXTRA_TOWN_KEYS,
    RoadExtras,
    RoadGeometry,
    SumoNetRef,
    check_strongly_connected,
    directed_pairs,
    identity_extras,
    parse_road_extras,
    shaped_roads,
)

# The paper's town with the geometry of CARLA Town01, where the authors ran their study
# (networks/data/PROVENANCE.md). An invented layout of the same roads and incidents is packaged
# as pentagon.json, to show what a layout alone does to the figures (docs/real_study.md).
DEFAULT_TOWN_PATH = Path(__file__).parent / "data" / "town01_carla.json"
PENTAGON_TOWN_PATH = Path(__file__).parent / "data" / "pentagon.json"
# Towns built on first use, by name: registered by networks/__init__.py (the town `city`,
# networks/cities.py, which imports this module).
BUILT_TOWNS: dict[str, Callable[[], Path]] = {}
TOWNS = PackagedKind("town", DEFAULT_TOWN_PATH.parent, ".json", built=BUILT_TOWNS)   # packaged towns by name
# The files `trustroute town import` makes a town of (networks/osm_convert.py): read as a town file,
# they would fail as JSON, so load_town names the import instead.
OSM_SUFFIXES: tuple[str, ...] = (".osm", ".osm.xml")
NET_SUFFIXES: tuple[str, ...] = (".net.xml", ".net.xml.gz")
NO_INCIDENT = "none"  # a road without an incident (and the start road of an episode)
INCIDENT_TYPES: tuple[str, ...] = ("obstacle", "pedestrian", "truck", NO_INCIDENT)
# SUMO works in metres with float coordinates: a town beyond 1000 km, or a road shorter than a car,
# passes the schema but breaks netconvert or makes every length degenerate.
MAX_COORDINATE = 1.0e6
MIN_ROAD_LENGTH = 10.0
MAX_JUNCTION_NAME = 64
JUNCTION_NAME = re.compile(r"[A-Za-z0-9_]+")


def rule_moves(neighbours: Mapping[str, Sequence[str]], directed_road: str) -> tuple[str, ...]:
    """The town's rule for the moves from U-V (docs/model.md): the neighbours of V other than U,
    and U itself only at a dead end."""
    came_from, at = Road.parse(directed_road)
    options = tuple(w for w in neighbours[at] if w != came_from)
    return options if options else (came_from,)


@dataclass(frozen=True)
class Town:
    """A validated town. `states` are the directed roads in a fixed sorted order; `neighbours` the
    junctions one road away in driving direction; `one_way` the (U, V) roads driven only from U to
    V; `geometry` the real course of the directed roads that have one; `turns` the moves of the
    directed roads whose moves are not the rule's (networks/road_geometry.py)."""

    junctions: dict[str, tuple[float, float]]
    roads: tuple[tuple[str, str], ...]
    incidents: dict[str, str]
    source_path: str = ""
    provenance: str = ""
    one_way: frozenset[tuple[str, str]] = frozenset()
    geometry: dict[str, RoadGeometry] = field(default_factory=dict)
    sumo_net: SumoNetRef | None = None
    turns: dict[str, tuple[str, ...]] = field(default_factory=dict)
    states: tuple[str, ...] = field(init=False)
    neighbours: dict[str, tuple[str, ...]] = field(init=False)

    def __post_init__(self) -> None:
        neighbours: dict[str, list[str]] = {name: [] for name in self.junctions}
        for u, v in directed_pairs(self.roads, self.one_way):
            neighbours[u].append(v)
        object.__setattr__(
            self, "neighbours", {k: tuple(sorted(v)) for k, v in neighbours.items()}
        )
        states = sorted(Road(u, v).id for u, v in directed_pairs(self.roads, self.one_way))
        object.__setattr__(self, "states", tuple(states))

    # -- identity -----------------------------------------------------------
    @functools.cached_property
    def content_hash(self) -> str:
        """SHA-256 of the town's content (not its file name or formatting)."""
        canonical = json.dumps(
            {
                "junctions": {k: list(v) for k, v in sorted(self.junctions.items())},
                "roads": sorted(sorted(r) for r in self.roads),
                "incidents": dict(sorted(self.incidents.items())),
                **identity_extras(self.one_way, self.geometry, self.sumo_net, self.turns),
            },
            sort_keys=True,
            separators=(",", ":"),
        )
        return hashlib.sha256(canonical.encode()).hexdigest()

    # -- states and actions -------------------------------------------------
    # Episodes ask for indices and moves at every junction: both are tables built once per town.
    @functools.cached_property
    def _state_indices(self) -> dict[str, int]:
        return {road: i for i, road in enumerate(self.states)}

    @functools.cached_property
    def _actions(self) -> dict[str, tuple[str, ...]]:
        return {road: self._moves(road) for road in self.states}

    @functools.cached_property
    def _successors(self) -> dict[tuple[str, str], str]:
        return {(road, w): Road(Road.parse(road).to_junction, w).id
                for road in self.states for w in self._actions[road]}

    @functools.cached_property
    def successor_table(self) -> np.ndarray:
        """int64 [n_states, widest move count], read-only: per state (in `states` order) the state
        index of each move's road, in the order of `actions`, padded with -1. The road graph as
        the trust POMDP and the free completion index it."""
        rows = [[self.state_index(nxt) for nxt in self.successors(road)] for road in self.states]
        table = np.full((len(rows), max(map(len, rows))), -1, dtype=np.int64)
        for x, row in enumerate(rows):
            table[x, :len(row)] = row
        table.setflags(write=False)
        return table

    def state_index(self, directed_road: str) -> int:
        index = self._state_indices.get(directed_road)
        if index is None:
            raise ValueError(f"{directed_road!r} is not a directed road of the town")
        return index

    def actions(self, directed_road: str) -> tuple[str, ...]:
        """Next junctions from state U-V: its `turns` entry when it has one, else the neighbours of
        V except U, unless V is a dead end; in the order of `neighbours`."""
        moves = self._actions.get(directed_road)
        return moves if moves is not None else self._moves(directed_road)

    def _moves(self, directed_road: str) -> tuple[str, ...]:
        allowed = self.turns.get(directed_road)
        if allowed is not None:
            return tuple(w for w in self.neighbours[Road.parse(directed_road).to_junction] if w in allowed)
        return rule_moves(self.neighbours, directed_road)

    def successor(self, directed_road: str, next_junction: str) -> str:
        road = self._successors.get((directed_road, next_junction))
        if road is not None:
            return road
        at = Road.parse(directed_road).to_junction
        if next_junction not in self.actions(directed_road):
            raise ValueError(f"{next_junction} is not a legal move from {directed_road}")
        return Road(at, next_junction).id

    def successors(self, directed_road: str) -> tuple[str, ...]:
        return tuple(self.successor(directed_road, w) for w in self.actions(directed_road))

    def incident(self, directed_road: str) -> str:
        return self.incidents[directed_road]

    # -- geometry -----------------------------------------------------------
    def length(self, directed_road: str) -> float:
        """Model road length in metres: the road's geometry when it has one, else the
        centre-to-centre Euclidean distance."""
        geometry = self.geometry.get(directed_road)
        if geometry is not None:
            return geometry.length
        u, v = Road.parse(directed_road)
        (x1, y1), (x2, y2) = self.junctions[u], self.junctions[v]
        return math.hypot(x2 - x1, y2 - y1)

    def route_length(self, route: Sequence[str]) -> float:
        """Length driven along a route of directed roads, not counting the first (start) road."""
        return sum(self.length(r) for r in route[1:])

    def shortest_route(self, start: str, targets: Iterable[str]) -> list[str] | None:
        """Shortest legal route (list of directed roads, start included) from state
        `start` to any state in `targets`; the start itself counts if it is a target.
        Returns None when no target is reachable."""
        target_set = set(targets)
        best = {start: 0.0}
        previous: dict[str, str] = {}
        queue = [(0.0, start)]
        while queue:
            dist, state = heapq.heappop(queue)
            if dist > best[state]:
                continue
            if state in target_set:
                route = [state]
                while route[-1] in previous:
                    route.append(previous[route[-1]])
                return route[::-1]
            for nxt in self.successors(state):
                nd = dist + self.length(nxt)
                if nd < best.get(nxt, math.inf):
                    best[nxt] = nd
                    previous[nxt] = state
                    heapq.heappush(queue, (nd, nxt))
        return None

    def reachable_states(self, start: str) -> set[str]:
        seen = {start}
        stack = [start]
        while stack:
            for nxt in self.successors(stack.pop()):
                if nxt not in seen:
                    seen.add(nxt)
                    stack.append(nxt)
        return seen


# -- loading and validation -------------------------------------------------
# Every key of a town file (docs/formats/town.md); the rules below check what a table cannot.

class TownValues(TypedDict):
    """A town file's checked values (FIELDS)."""

    junctions: dict[str, object]
    roads: list[object]
    incidents: dict[str, str]
    source: object
    one_way: object     # checked by networks/road_geometry.py
    geometry: object
    sumo_net: object
    turns: object


FIELDS = field_table(
    TownValues,
    Field(key="junctions", kind=Table(nonempty=True), required=True,
          problem="expected a non-empty object of name -> [x, y]",
          fix="list each junction as \"A\": [x, y] in metres",
          missing_fix="add a 'junctions' entry as in the default town (trustroute net build --help)"),
    Field(key="roads", kind=ListOf(min_items=1), required=True,
          problem="expected a non-empty list of [U, V] pairs",
          fix="list each two-way road once as [\"A\", \"B\"]",
          missing_fix="add a 'roads' entry as in the default town (trustroute net build --help)"),
    Field(key="incidents", kind=Table(values=OneOf(choices=INCIDENT_TYPES, noun="incident type")),
          required=True,
          problem="expected an object of \"U-V\" -> incident type", fix="write one entry per directed road",
          missing_fix="add a 'incidents' entry as in the default town (trustroute net build --help)"),
    Field(key="source", kind=Anything(), default=""),  # provenance, kept as text
    # one-way roads, road geometry, the source SUMO net and turns: checked by networks/road_geometry.py
    *(Field(key=key, kind=Anything(), default=None) for key in EXTRA_TOWN_KEYS),
)
TOWN_KEYS: tuple[str, ...] = keys(FIELDS)
JUNCTION = Text(max_length=MAX_JUNCTION_NAME, pattern=JUNCTION_NAME)
COORDINATES = ListOf(item=Number(), min_items=2, max_items=2)
NEAR_ORIGIN = ListOf(item=Number(minimum=-MAX_COORDINATE, maximum=MAX_COORDINATE))
ROAD = ListOf(item=Text(nonempty=False), min_items=2, max_items=2)


def _junctions(raw: Mapping[str, object], path: str) -> dict[str, tuple[float, float]]:
    """Names of letters, digits and '_'; coordinates two finite numbers within MAX_COORDINATE."""
    junctions: dict[str, tuple[float, float]] = {}
    for name, xy in raw.items():
        place = f"junctions.{name}"
        check_value(name, JUNCTION, path, place, f"junction names must be 1-{MAX_JUNCTION_NAME} letters, "
                    "digits or '_' and contain no '-' (it joins road names)", "rename the junction")
        x, y = check_value(xy, COORDINATES, path, place,
                           f"coordinates {shown_value(xy, 60)} are not two finite numbers",
                           "write [x, y] in metres, e.g. [0, 700]")
        check_value(xy, NEAR_ORIGIN, path, place,
                    f"coordinates {shown_value(xy, 60)} lie more than {MAX_COORDINATE:g} m from the origin",
                    "give coordinates in metres of one town")
        junctions[name] = (float(x), float(y))
    return junctions


def _road(road: object, place: str, junctions: dict[str, tuple[float, float]], path: str,
          shaped: set[str]) -> tuple[str, str]:
    """One [U, V] pair: two known, different junctions at least MIN_ROAD_LENGTH apart (a road with
    a geometry has its own length: its junctions may stand closer than a car, not at one point,
    where their coordinates would say nothing of where the road runs)."""
    u, v = check_value(road, ROAD, path, place, f"{shown_value(road, 60)} is not a pair of junction names",
                       "write the road as [\"U\", \"V\"]")
    for j in (u, v):
        if j not in junctions:
            raise InputError(path, place, f"road {u}-{v} names unknown junction '{j}'",
                             f"add '{j}' to junctions or fix the road")
    if u == v:
        raise InputError(path, place, f"road {u}-{v} is a self-loop", "remove it; roads join two "
                         "different junctions")
    apart = math.dist(junctions[u], junctions[v])
    if apart == 0 or (not {Road(u, v).id, Road(v, u).id} & shaped and apart < MIN_ROAD_LENGTH):
        raise InputError(path, place, f"road {u}-{v} is {math.dist(junctions[u], junctions[v]):.3g} m long "
                         f"(junctions {u} and {v} almost coincide)", f"place the junctions at least "
                         f"{MIN_ROAD_LENGTH:g} m apart")
    return u, v


def _roads(raw: list[object], junctions: dict[str, tuple[float, float]], path: str,
           shaped: set[str]) -> tuple[tuple[str, str], ...]:
    """Every road valid and listed once ([A, B] and [B, A] are the same two-way road)."""
    roads: list[tuple[str, str]] = []
    seen: set[frozenset[str]] = set()
    for i, road in enumerate(raw):
        u, v = _road(road, f"roads[{i}]", junctions, path, shaped)
        if frozenset((u, v)) in seen:
            raise InputError(path, f"roads[{i}]", f"road {u}-{v} is listed twice (roads are two-way)",
                             "list each road once")
        seen.add(frozenset((u, v)))
        roads.append((u, v))
    return tuple(roads)


SHOWN_MISSING = 5  # directed roads named in the message when many lack an incident entry


def _check_incidents(incidents: Mapping[str, str], roads: tuple[tuple[str, str], ...],
                     one_way: frozenset[tuple[str, str]], path: str) -> None:
    """Exactly one entry per directed road of the town (one direction only for one-way roads)."""
    directed = {Road(a, b).id for a, b in directed_pairs(roads, one_way)}
    missing = sorted(key for key in directed if key not in incidents)
    if len(missing) == 1:
        raise InputError(path, f"incidents.{missing[0]}",
                         f"missing incident entry for directed road {missing[0]}",
                         f"add \"{missing[0]}\": one of {', '.join(INCIDENT_TYPES)}")
    if missing:
        shown = ", ".join(missing[:SHOWN_MISSING])
        more = f" and {len(missing) - SHOWN_MISSING} more" if len(missing) > SHOWN_MISSING else ""
        raise InputError(path, f"incidents.{missing[0]}", f"missing incident entries for {len(missing)} "
                         f"directed roads: {shown}{more}", "add one entry per direction of every road, "
                         f"e.g. \"{missing[0]}\": one of {', '.join(INCIDENT_TYPES)}")
    for key in incidents:
        if key not in directed:
            raise InputError(path, f"incidents.{key}", f"'{key}' is not a directed road of this town",
                             "remove the entry or add the road")


def _check_connected(town: Town, path: str) -> None:
    """Every junction reachable from the first along the roads (both ways unless one-way), and
    every junction reachable from every other where roads are one-way."""
    first = next(iter(town.junctions))
    reached = {first}
    stack = [first]
    while stack:
        for w in town.neighbours[stack.pop()]:
            if w not in reached:
                reached.add(w)
                stack.append(w)
    if len(reached) != len(town.junctions):
        missing = sorted(set(town.junctions) - reached)
        raise InputError(path, "roads", f"the town is disconnected: {', '.join(missing)} cannot be "
                         f"reached from {first}", "add roads joining every junction")
    check_strongly_connected(town.junctions, town.neighbours, town.one_way, path)


def town_from_dict(data: object, path: str = "<town>") -> Town:
    """Validate a parsed town document and build a Town, or raise InputError."""
    data = require_object(data, path, "write {\"junctions\": ..., \"roads\": ..., \"incidents\": ...}")
    values = check_fields(data, FIELDS, path, "town file")
    junctions = _junctions(values["junctions"], path)
    roads = _roads(values["roads"], junctions, path, shaped_roads(data))
    extras = parse_road_extras(data, path, roads)
    _check_incidents(values["incidents"], roads, extras.one_way, path)
    town = Town(junctions=junctions, roads=roads, incidents=dict(values["incidents"]),
                source_path=path, provenance=str(values["source"]), **extras_fields(extras))
    _check_connected(town, path)
    return town


def extras_fields(extras: RoadExtras) -> dict:
    """The Town fields of the optional road keys (networks/road_geometry.py)."""
    return {"one_way": extras.one_way, "geometry": dict(extras.geometry or {}), "sumo_net": extras.sumo_net,
            "turns": dict(extras.turns or {})}


def town_file(path: str | Path | None) -> Path:
    """The file a town argument or a study's recorded town names: `TOWNS.resolve`, the packaged
    default town for None."""
    return TOWNS.resolve(path) if path is not None else DEFAULT_TOWN_PATH


def load_town(path: str | Path | None = None, given: str = "--town") -> Town:
    """Load and validate a town file or a packaged town by name (`TOWNS`: "town01_carla",
    "pentagon", "city"; the packaged default when `path` is None), read through the guarded reader
    (trustroute.core.validation). `given`: how the command line takes it, named in the hint when it
    cannot be read (PackagedKind.fix)."""
    file_path = town_file(path)
    shown = "default town" if path is None else str(path if file_path == Path(path) else file_path)
    if file_path.name.lower().endswith(NET_SUFFIXES + OSM_SUFFIXES) and file_path.is_file():
        raise InputError(shown, "", "a SUMO net or an OpenStreetMap file, not a town file (JSON)",
                         f"import it as a town first: trustroute town import {shown} --out town.json, "
                         f"then pass town.json{passed_how(given)}")
    text = read_text(file_path, shown, "the town file", TOWNS.fix(given))
    return town_from_dict(parse_json(text, shown, "town file"), shown)
