"""The net an episode on a built town drives, checked once per process: built and verified
(`town_net`), readable (`check_readable`) and holding an edge for every road of the town
(`check_net_matches`), each keyed by the file's path and mtime (`net_key`)."""

from __future__ import annotations

from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.networks.sumo_net import build_net, net_counts
from trustroute.networks.sumo_net import net_path as town_net_path

_MATCHING_NETS: set[tuple[str, float, str]] = set()


def check_net_matches(sumo, setup: EpisodeSetup, net_path: Path, net_key: tuple[str, float]) -> None:
    """The net has an edge for every road of the town (checked once per net and town per process)."""
    key = (*net_key, setup.town.content_hash)
    if key in _MATCHING_NETS:
        return
    edges = set(sumo.edge.getIDList())
    missing = sorted(set(setup.town.states) - edges)
    if missing:
        raise InputError(str(net_path), "", f"the net has no edge for road(s) {', '.join(missing[:4])} of "
                         f"town {setup.town.source_path or 'town'}",
                         "build the net of this town with `trustroute net build --town FILE`")
    _MATCHING_NETS.add(key)


_READABLE: set[tuple[str, float]] = set()
_VERIFIED_NETS: set[tuple[str, str, int]] = set()


def town_net(town) -> Path:
    """`build_net(town).path`, verified once per process and version of the cached file (its
    path and mtime): build_net parses the whole net to verify it, which in a study cost about
    5 ms of every episode. A replaced or deleted file is verified (or rebuilt) again."""
    target = town_net_path(town)
    try:
        key = (town.content_hash, str(target), target.stat().st_mtime_ns)
    except OSError:
        key = None
    if key in _VERIFIED_NETS:
        return target
    path = build_net(town).path
    _VERIFIED_NETS.add((town.content_hash, str(path), path.stat().st_mtime_ns))
    return path


def net_key(net_path: Path) -> tuple[str, float]:
    """(path, mtime) of a net: what the once-per-process checks are keyed on (one stat per episode)."""
    try:
        return str(net_path), net_path.stat().st_mtime
    except OSError:
        raise InputError(str(net_path), "", "the SUMO net file does not exist",
                         "run `trustroute net build` or pass an existing .net.xml") from None


def check_readable(net_path: Path, key: tuple[str, float]) -> None:
    """Parse a net passed in once per (path, mtime): a clear one-line error before SUMO prints its own."""
    if key not in _READABLE:
        net_counts(net_path)
        _READABLE.add(key)
