"""The optional keys of a town file that describe real roads: one-way roads, road shapes and
lengths, and the SUMO net a town was imported from (docs/formats/town.md).

- `one_way`: roads of `roads` that are driven in one direction only;
- `geometry`: per directed road its polyline `shape`, its driven `length` (the shape's length when
  absent), the SUMO `edges` it runs along and its `street` name;
- `sumo_net`: the source net's file and SHA-256, so a town can tell when its net has changed;
- `turns`: per directed road the next junctions it may turn to, where the road's moves differ from
  the town's rule (a net that forbids a turn, or allows a U-turn where nothing else is driveable).

A town without these keys is the two-way, straight-road town the format started with; its content
hash leaves them out (`identity_extras`), so nets and policy files keyed by it stay valid.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.core.package import SHA256_HEX
from trustroute.core.validation import check_keys
from trustroute.core.wording import shown_value
from trustroute.networks.road import Road

EXTRA_TOWN_KEYS: tuple[str, ...] = ("one_way", "geometry", "sumo_net", "turns")
GEOMETRY_KEYS: tuple[str, ...] = ("shape", "length", "edges", "street")


@dataclass(frozen=True)
class RoadGeometry:
    """The real course of one directed road: polyline, driven length, SUMO edges, street name."""

    shape: tuple[tuple[float, float], ...]
    length: float
    edges: tuple[str, ...] = ()
    street: str = ""

    def to_dict(self) -> dict:
        out: dict = {"shape": [list(point) for point in self.shape], "length": self.length}
        if self.edges:
            out["edges"] = list(self.edges)
        if self.street:
            out["street"] = self.street
        return out


@dataclass(frozen=True)
class SumoNetRef:
    """The SUMO net a town was imported from: its file (relative to the town file's folder unless
    absolute) and the SHA-256 of its bytes."""

    file: str
    sha256: str

    def to_dict(self) -> dict:
        return {"file": self.file, "sha256": self.sha256}


@dataclass(frozen=True)
class RoadExtras:
    one_way: frozenset[tuple[str, str]] = frozenset()
    geometry: Mapping[str, RoadGeometry] | None = None
    sumo_net: SumoNetRef | None = None
    turns: Mapping[str, tuple[str, ...]] | None = None


def polyline_length(shape: Iterable[tuple[float, float]]) -> float:
    points = list(shape)
    return sum(math.dist(a, b) for a, b in zip(points, points[1:], strict=False))


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def directed_pairs(roads: Iterable[tuple[str, str]],
                   one_way: frozenset[tuple[str, str]] = frozenset()) -> list[tuple[str, str]]:
    """The directed roads (U, V) of a town: both directions of every road, except the closed
    direction of a one-way road."""
    out = []
    for u, v in roads:
        for a, b in ((u, v), (v, u)):
            if (b, a) not in one_way:
                out.append((a, b))
    return out


def shaped_roads(data: Mapping) -> set[str]:
    """Directed road names that carry a geometry entry (read before the entries are validated)."""
    geometry = data.get("geometry")
    return {key for key in geometry if isinstance(key, str)} if isinstance(geometry, dict) else set()


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def parse_one_way(data: Mapping, path: str, roads: Iterable[tuple[str, str]]) -> frozenset[tuple[str, str]]:
    raw = data.get("one_way", [])
    if not isinstance(raw, list):
        raise InputError(path, "one_way", "expected a list of [U, V] pairs",
                         "list each one-way road as [\"U\", \"V\"] in its driving direction")
    known = {frozenset(road) for road in roads}
    seen: set[frozenset[str]] = set()
    out = set()
    for i, pair in enumerate(raw):
        place = f"one_way[{i}]"
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(j, str) for j in pair)):
            raise InputError(path, place, f"{shown_value(pair, 60)} is not a pair of junction names",
                             "write the one-way road as [\"U\", \"V\"]")
        key = frozenset(pair)
        if key not in known:
            raise InputError(path, place, f"{pair[0]}-{pair[1]} is not listed in roads",
                             "list the road in roads as well, or remove it from one_way")
        if key in seen:
            raise InputError(path, place, f"road {pair[0]}-{pair[1]} is one-way twice",
                             "list each one-way road once (a road driven both ways is not one-way)")
        seen.add(key)
        out.add((pair[0], pair[1]))
    return frozenset(out)


def parse_shape(raw: object, path: str, place: str) -> tuple[tuple[float, float], ...]:
    if not (isinstance(raw, list) and len(raw) >= 2 and all(
            isinstance(p, list) and len(p) == 2 and all(_is_number(c) for c in p) for p in raw)):
        raise InputError(path, place, "a shape must be a list of at least two [x, y] points of finite "
                         "numbers", "write the road's course as [[x, y], [x, y], ...] in metres")
    return tuple((float(p[0]), float(p[1])) for p in raw)


def parse_geometry_entry(raw: object, path: str, place: str) -> RoadGeometry:
    if not isinstance(raw, dict) or "shape" not in raw:
        raise InputError(path, place, "expected an object with a \"shape\"",
                         "write {\"shape\": [[x, y], ...], \"length\": metres}")
    check_keys(raw, GEOMETRY_KEYS, path, place, "geometry entry")
    shape = parse_shape(raw["shape"], path, f"{place}.shape")
    length = raw.get("length", polyline_length(shape))
    if not _is_number(length) or length <= 0:
        raise InputError(path, f"{place}.length", f"length {shown_value(length)} is not a positive number "
                         "of metres", "give the driven length in metres, or a shape that is not a point")
    edges = raw.get("edges", [])
    if not (isinstance(edges, list) and all(isinstance(e, str) and e for e in edges)):
        raise InputError(path, f"{place}.edges", "expected a list of SUMO edge ids",
                         "list the ids of the net's edges the road runs along, in driving order")
    street = raw.get("street", "")
    if not isinstance(street, str):
        raise InputError(path, f"{place}.street", "expected text", "write the street name as a string")
    return RoadGeometry(shape=shape, length=float(length), edges=tuple(edges), street=street)


def parse_sumo_net(data: Mapping, path: str) -> SumoNetRef | None:
    raw = data.get("sumo_net")
    if raw is None:
        return None
    if not (isinstance(raw, dict) and set(raw) == {"file", "sha256"} and isinstance(raw["file"], str)
            and raw["file"] and isinstance(raw["sha256"], str) and SHA256_HEX.fullmatch(raw["sha256"])):
        raise InputError(path, "sumo_net", "expected {\"file\": path, \"sha256\": 64 lowercase hex digits}",
                         "re-import the town with trustroute town import, or remove sumo_net")
    return SumoNetRef(file=raw["file"], sha256=raw["sha256"])


def parse_turns(data: Mapping, path: str, directed: Iterable[tuple[str, str]]) -> dict[str, tuple[str, ...]]:
    """The `turns` entries: a directed road "U-V" -> the junctions W (sorted, each once) of the
    directed roads V-W it may turn into; W may be U (a U-turn, where the source net allows one)."""
    raw = data.get("turns", {})
    if not isinstance(raw, dict):
        raise InputError(path, "turns", "expected an object of \"U-V\" -> [next junction, ...]",
                         "key each restricted road's moves by its directed road name")
    directed = list(directed)
    leaving: dict[str, set[str]] = {}
    for u, v in directed:
        leaving.setdefault(u, set()).add(v)
    names = {Road(u, v).id: v for u, v in directed}
    out = {}
    for key, moves in raw.items():
        place = f"turns.{key}"
        if key not in names:
            raise InputError(path, place, f"'{key}' is not a directed road of this town",
                             "remove the entry or add the road (a one-way road has one direction only)")
        if not (isinstance(moves, list) and moves and all(isinstance(w, str) for w in moves)
                and len(set(moves)) == len(moves)):
            raise InputError(path, place, "expected a non-empty list of junction names, each once",
                             "list the junctions the road may turn to, e.g. [\"W\"]")
        at = names[key]
        for w in moves:
            if w not in leaving.get(at, set()):
                raise InputError(path, place, f"{Road(at, w).id} is not a directed road of this town",
                                 f"list only junctions one road on from {at} in driving direction")
        out[key] = tuple(sorted(moves))
    return dict(sorted(out.items()))


def parse_road_extras(data: Mapping, path: str, roads: Iterable[tuple[str, str]]) -> RoadExtras:
    """Validate the optional keys `one_way`, `geometry`, `sumo_net` and `turns` of a town document."""
    roads = list(roads)
    one_way = parse_one_way(data, path, roads)
    raw_geometry = data.get("geometry", {})
    if not isinstance(raw_geometry, dict):
        raise InputError(path, "geometry", "expected an object of \"U-V\" -> {\"shape\": ...}",
                         "key each road's geometry by its directed road name")
    directed = {Road(u, v).id for u, v in directed_pairs(roads, one_way)}
    geometry = {}
    for key, raw in raw_geometry.items():
        if key not in directed:
            raise InputError(path, f"geometry.{key}", f"'{key}' is not a directed road of this town",
                             "remove the entry or add the road (a one-way road has one direction only)")
        geometry[key] = parse_geometry_entry(raw, path, f"geometry.{key}")
    return RoadExtras(one_way=one_way, geometry=dict(sorted(geometry.items())),
                      sumo_net=parse_sumo_net(data, path),
                      turns=parse_turns(data, path, directed_pairs(roads, one_way)))


def check_strongly_connected(junctions: Iterable[str], out_neighbours: Mapping[str, Iterable[str]],
                             one_way: frozenset[tuple[str, str]], path: str) -> None:
    """Every junction reaches every other along directed roads (a one-way road can cut a town that
    is connected when its roads are taken both ways; without one, connected is enough)."""
    if not one_way:
        return
    names = sorted(junctions)
    incoming: dict[str, list[str]] = {name: [] for name in names}
    for u in names:
        for v in out_neighbours[u]:
            incoming[v].append(u)
    first = names[0]
    for graph, words in ((out_neighbours, "cannot be reached from"), (incoming, "cannot reach")):
        reached = {first}
        stack = [first]
        while stack:
            for w in graph[stack.pop()]:
                if w not in reached:
                    reached.add(w)
                    stack.append(w)
        if len(reached) != len(names):
            missing = sorted(set(names) - reached)
            raise InputError(path, "one_way", f"the one-way roads cut the town: {', '.join(missing[:5])} "
                             f"{words} {first}", "open a direction of a one-way road, or add roads")


def identity_extras(one_way: frozenset[tuple[str, str]], geometry: Mapping[str, RoadGeometry],
                    sumo_net: SumoNetRef | None, turns: Mapping[str, tuple[str, ...]] | None = None) -> dict:
    """The extra keys of a town's canonical content (only those present, so a town without them
    keeps its hash)."""
    out: dict = {}
    if one_way:
        out["one_way"] = sorted(list(pair) for pair in one_way)
    if geometry:
        out["geometry"] = {key: value.to_dict() for key, value in sorted(geometry.items())}
    if sumo_net is not None:
        out["sumo_net_sha256"] = sumo_net.sha256
    if turns:
        out["turns"] = {key: list(moves) for key, moves in sorted(turns.items())}
    return out


def check_sumo_net(net: SumoNetRef, town_path: str) -> Path:
    """The town's source net, checked against its recorded SHA-256, or InputError."""
    file = Path(net.file)
    if not file.is_absolute():
        file = Path(town_path).parent / file
    if not file.is_file():
        raise InputError(town_path, "sumo_net.file", f"the town's SUMO net {file} does not exist",
                         "put the net beside the town file or re-import the town")
    if file_sha256(file) != net.sha256:
        raise InputError(town_path, "sumo_net.sha256", f"the SUMO net {file} has changed since the town "
                         "was imported", "re-import the town with trustroute town import")
    return file
