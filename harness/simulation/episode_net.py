"""The net an episode on a built town drives (`net_for`, trustroute/app/nets.py), checked once per
process: readable (`check_readable`) and holding an edge for every road of the town
(`check_net_matches`), each keyed by the file's path and mtime (`net_key`)."""

from __future__ import annotations

from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.networks.sumo_import import require_net_file
from trustroute.networks.sumo_net import net_counts

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


def net_key(net_path: Path) -> tuple[str, float]:
    """(path, mtime) of a net: what the once-per-process checks are keyed on (one stat per episode)."""
    try:
        return str(net_path), net_path.stat().st_mtime
    except OSError:
        require_net_file(net_path)
        raise


def check_readable(net_path: Path, key: tuple[str, float]) -> None:
    """Parse a net passed in once per (path, mtime): a clear one-line error before SUMO prints its own."""
    if key not in _READABLE:
        net_counts(net_path)
        _READABLE.add(key)
