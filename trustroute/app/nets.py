"""`net_for(town)`: the one answer to "which SUMO net does this town drive".

A town imported from a SUMO net (`trustroute town import`, the packaged `city` and `csomor`) drives
that net, its content checked against the hash the town recorded; any other town drives the net
built from its junctions and roads (networks/sumo_net.py, cached by content hash). Episodes, the
`run` command, the live station's view and the live replay's recordings all ask here.
"""

from __future__ import annotations

from pathlib import Path

from trustroute.networks.real_net import is_imported, town_net_file
from trustroute.networks.sumo_net import build_net
from trustroute.networks.sumo_net import net_path as built_net_path
from trustroute.networks.town import Town

# (town content hash, path, mtime) of built nets verified in this process: build_net parses the
# whole net to verify it, which in a study cost about 5 ms of every episode. A cache of files on
# disk, keyed by the file's version: a replaced or deleted file is verified (or rebuilt) again.
_VERIFIED_NETS: set[tuple[str, str, int]] = set()


def net_for(town: Town) -> Path:
    """The SUMO net `town` drives: its imported net, else its built net (built when missing)."""
    if is_imported(town):
        return town_net_file(town)
    return built_net(town)


def built_net(town: Town) -> Path:
    """`build_net(town).path`, verified once per process and version of the cached file."""
    target = built_net_path(town)
    try:
        key = (town.content_hash, str(target), target.stat().st_mtime_ns)
    except OSError:
        key = None
    if key in _VERIFIED_NETS:
        return target
    path = build_net(town).path
    _VERIFIED_NETS.add((town.content_hash, str(path), path.stat().st_mtime_ns))
    return path
