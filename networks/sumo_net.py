"""The SUMO network of a town: plain XML -> netconvert -> `.net.xml`, cached by content hash.

Recipe (one place: `plain_xml` and `netconvert_command`): one edge per directed road with id
"U-V", one vehicle lane at 13.89 m/s (lane 1) beside a sidewalk (lane 0) on every edge; the
vehicle lanes of U-V and V-U are declared opposite-direction neighbours (`<neigh>` in the plain
edge file), so SUMO lets a vehicle overtake through the oncoming lane (docs/scenes.md); a
prioritised pedestrian crossing over each road with a pedestrian incident, at both of its ends
(the person of a `U-V` incident crosses at U, ahead of the ego as it turns into `U-V`); explicit
connections to every non-U-turn successor (U-turns only at dead ends, `--no-turnarounds`);
narrow lanes and small junction radii so that driven lengths (edge + internal lanes of the
connection taken) stay within 5 % of the model's Euclidean lengths on long straight roads
(docs/model.md, "Road lengths"); a road whose geometry bends between its junctions is drawn
along that shape (`edge_shape`; its opposite direction along the same shape reversed), so that
it is driven as long as the model counts it.
One vehicle lane per direction keeps lane choice out of routing: the route can be extended one road ahead late
on the current road, after its incident has been observed.

The net is written atomically (temp file + rename) to `<cache>/<town hash>-<recipe>.net.xml`; a
second build of the same town is a cache hit. netconvert comes from the eclipse-sumo wheel via
`sumolib.checkBinary`, so no SUMO_HOME is needed.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from trustroute.core.cache import NETS, entry_lock_path
from trustroute.core.cache import cache_dir as default_cache_dir
from trustroute.core.errors import InputError
from trustroute.core.output_files import file_lock
from trustroute.networks.road import Road
from trustroute.networks.town import Town

NET_RECIPE = "r3"                      # bump when the recipe below changes: invalidates caches
ROAD_SPEED = 13.89                     # m/s (50 km/h)
LANE_WIDTH = 3.0
SIDEWALK_WIDTH = 1.5
VEHICLE_LANES = 1


@dataclass(frozen=True)
class NetBuild:
    """A built (or cached) SUMO net and its counts (internal and pedestrian elements excluded
    from `edges` and `connections`; `crossings` counts pedestrian crossings)."""

    path: Path
    cached: bool
    seconds: float
    edges: int
    junctions: int
    connections: int
    crossings: int

    def to_dict(self) -> dict:
        return {"path": str(self.path), "cached": self.cached, "seconds": self.seconds,
                "edges": self.edges, "junctions": self.junctions, "connections": self.connections,
                "crossings": self.crossings}


def find_binary(name: str) -> str:
    """Path of a SUMO binary from the eclipse-sumo wheel (or SUMO_HOME), or InputError."""
    import sumolib

    found = sumolib.checkBinary(name)
    if not os.path.isfile(found):
        found = shutil.which(found) or ""
    if not found or not os.access(found, os.X_OK):
        raise InputError(name, "", f"the SUMO binary '{name}' was not found",
                         "install the pinned eclipse-sumo wheel (pip install -e .) or set SUMO_HOME")
    return found


def pedestrian_roads(town: Town) -> list[tuple[str, str]]:
    """Undirected roads (sorted pairs) with a pedestrian incident in either direction."""
    incident = town.incidents.get  # a one-way road has one direction only
    return sorted({(u, v) if u <= v else (v, u) for u, v in town.roads
                   if "pedestrian" in (incident(Road(u, v).id), incident(Road(v, u).id))})


def lane_count(town: Town, directed_road: str) -> int:
    """Vehicle lanes of a road (the sidewalk not counted)."""
    return VEHICLE_LANES


def opposite_lane(town: Town, directed_road: str) -> str:
    """The SUMO lane id of a road's leftmost vehicle lane (the one its opposite direction neighbours)."""
    return f"{directed_road}_{lane_count(town, directed_road)}"


def edge_shape(town: Town, directed_road: str) -> tuple[tuple[float, float], ...] | None:
    """The course netconvert draws a road's edge along: the road's geometry shape, or the opposite
    direction's shape reversed, when it bends between the junctions; None for a straight road (the
    edge is then drawn from junction to junction and the plain XML carries no shape)."""
    own = town.geometry.get(directed_road)
    if own is not None and len(own.shape) > 2:
        return own.shape
    u, v = Road.parse(directed_road)
    other = town.geometry.get(Road(v, u).id)
    if other is not None and len(other.shape) > 2:
        return tuple(reversed(other.shape))
    return None


def _shape_attribute(town: Town, directed_road: str) -> str:
    shape = edge_shape(town, directed_road)
    if shape is None:
        return ""
    return " shape=\"" + " ".join(f"{x:.3f},{y:.3f}" for x, y in shape) + "\""


def plain_xml(town: Town) -> dict[str, str]:
    """The plain-XML inputs of netconvert: {"nod": ..., "edg": ..., "con": ...}."""
    walk = {frozenset(pair) for pair in pedestrian_roads(town)}
    nodes = ["<nodes>"]
    for name, (x, y) in sorted(town.junctions.items()):
        nodes.append(f"  <node id={quoteattr(name)} x=\"{x:.3f}\" y=\"{y:.3f}\" type=\"priority\"/>")
    nodes.append("</nodes>")
    edges = ["<edges>"]
    for road in town.states:
        u, v = Road.parse(road)
        reverse = Road(v, u).id
        edges.append(f"  <edge id={quoteattr(road)} from={quoteattr(u)} to={quoteattr(v)} priority=\"1\" "
                     f"numLanes=\"{lane_count(town, road)}\" speed=\"{ROAD_SPEED}\" "
                     f"width=\"{LANE_WIDTH}\" sidewalkWidth=\"{SIDEWALK_WIDTH}\" spreadType=\"right\""
                     f"{_shape_attribute(town, road)}>")
        if reverse in town.states:
            # The leftmost vehicle lane of the opposite direction: overtaking through it is allowed.
            edges.append(f"    <neigh lane={quoteattr(opposite_lane(town, reverse))}/>")
        edges.append("  </edge>")
    edges.append("</edges>")
    connections = ["<connections>"]
    for road in town.states:
        for nxt in town.successors(road):
            # Lane 0 of every edge is its sidewalk: vehicle lanes start at 1.
            for lane in range(1, lane_count(town, road) + 1):
                connections.append(f"  <connection from={quoteattr(road)} to={quoteattr(nxt)} "
                                   f"fromLane=\"{lane}\" toLane=\"1\"/>")
    for u, v in sorted(tuple(sorted(p)) for p in walk):
        for at in (u, v):
            connections.append(f"  <crossing node={quoteattr(at)} edges=\"{Road(u, v).id} "
                               f"{Road(v, u).id}\" priority=\"true\"/>")
    connections.append("</connections>")
    return {"nod": "\n".join(nodes) + "\n", "edg": "\n".join(edges) + "\n",
            "con": "\n".join(connections) + "\n"}


def netconvert_command(binary: str, plain: dict[str, Path], output: Path) -> list[str]:
    """Every netconvert option of the recipe, in one list."""
    return [
        binary,
        "--node-files", str(plain["nod"]),
        "--edge-files", str(plain["edg"]),
        "--connection-files", str(plain["con"]),
        "--output-file", str(output),
        "--no-turnarounds", "true",             # U-turns only where the connection file asks (dead ends)
        "--offset.disable-normalization", "true",  # keep the town's coordinates
        "--default.junctions.radius", "2",
        "--junctions.corner-detail", "0",
        "--walkingareas", "true",
        "--crossings.guess", "false",
        "--no-warnings", "true",
        "--seed", "1",
    ]


def net_counts(path: Path) -> dict[str, int]:
    """Counts of a .net.xml; InputError when it is unreadable or not a SUMO net."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise InputError(str(path), "", f"not a readable SUMO net ({exc})",
                         "delete the file and run `trustroute net build` again") from None
    if root.tag != "net":
        raise InputError(str(path), "", f"not a SUMO net (root element <{root.tag}>)",
                         "pass a .net.xml written by netconvert (`trustroute net build`)")
    edges = [e for e in root.iter("edge") if e.get("function") is None]
    crossings = [e for e in root.iter("edge") if e.get("function") == "crossing"]
    junctions = [j for j in root.iter("junction") if j.get("type") != "internal"]
    road_ids = {e.get("id") for e in edges}
    connections = [c for c in root.iter("connection")
                   if c.get("from") in road_ids and c.get("to") in road_ids]
    return {"edges": len(edges), "junctions": len(junctions), "connections": len(connections),
            "crossings": len(crossings)}


def net_path(town: Town, cache_dir: Path | None = None) -> Path:
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir(NETS)
    return directory / f"{town.content_hash}-{NET_RECIPE}.net.xml"


def _looks_complete(path: Path) -> bool:
    # A cheap cache check: a net cut short by a crash lacks the closing tag.
    try:
        with path.open("rb") as handle:
            handle.seek(max(0, path.stat().st_size - 64))
            return b"</net>" in handle.read()
    except OSError:
        return False


def _cached(town: Town, target: Path, started: float, notice: Callable[[str], object]) -> NetBuild | None:
    """The cache entry if it verifies (complete, parses as a SUMO net); a damaged one is removed
    with a one-line notice so that it is rebuilt."""
    if not target.exists():
        return None
    try:
        if not (target.is_file() and _looks_complete(target)):
            raise InputError(str(target), "", "the cached net is incomplete", "")
        counts = net_counts(target)
        if counts["edges"] != len(town.states):
            raise InputError(str(target), "", f"the cached net has {counts['edges']} roads, the town "
                             f"{len(town.states)}", "")
    except InputError as exc:
        notice(f"notice: discarding the damaged net cache entry {target.name} ({exc.problem}); "
               "building it again")
        with contextlib.suppress(FileNotFoundError):
            target.unlink()
        return None
    return NetBuild(path=target, cached=True, seconds=time.perf_counter() - started, **counts)


def _stderr(message: str) -> None:
    print(message, file=sys.stderr)


def build_net(town: Town, cache_dir: Path | None = None,
              notice: Callable[[str], object] = _stderr) -> NetBuild:
    """The SUMO net of `town`, built with netconvert or taken from the cache. The entry is verified
    on every read, built under a lock (two processes never build one entry at once) and written
    atomically (fsync, then rename)."""
    started = time.perf_counter()
    target = net_path(town, cache_dir)
    found = _cached(town, target, started, notice)
    if found is not None:
        return found
    binary = find_binary("netconvert")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(str(target.parent), "", f"cannot create the net cache ({exc.strerror})",
                         "pass a writable directory with --out") from None
    with file_lock(entry_lock_path(target), "net cache entry", wait=True,
                   fix="pass a writable directory with --out"):
        found = _cached(town, target, started, notice)  # built while we waited?
        if found is not None:
            return found
        _netconvert(town, binary, target)
    counts = net_counts(target)
    return NetBuild(path=target, cached=False, seconds=time.perf_counter() - started, **counts)


def _netconvert(town: Town, binary: str, target: Path) -> None:
    with tempfile.TemporaryDirectory(prefix="trustroute-net-", dir=target.parent) as work:
        work_dir = Path(work)
        plain = {}
        for kind, text in plain_xml(town).items():
            plain[kind] = work_dir / f"town.{kind}.xml"
            plain[kind].write_text(text)
        output = work_dir / "town.net.xml"
        result = subprocess.run(netconvert_command(binary, plain, output), capture_output=True, text=True,
                                check=False)
        if result.returncode != 0 or not output.is_file():
            message = (result.stderr or result.stdout).strip().splitlines()
            raise InputError(town.source_path or "town", "", "netconvert failed: "
                             + (message[-1] if message else f"exit {result.returncode}"),
                             "check the town's coordinates (roads must have positive length)")
        with open(output, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(output, target)   # atomic on one file system: readers never see half a net
