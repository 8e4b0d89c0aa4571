"""The one cache root of trustroute: `$XDG_CACHE_HOME/trustroute`, default `~/.cache/trustroute`.

Built SUMO nets (`nets/`, networks/sumo_net.py), synthesized "aware" policies (`policies/`,
policies/resolve.py) and the towns imported on first use (`towns/`, networks/cities.py) live
under it. The root is read when a cache path is asked for, not
at import, so setting XDG_CACHE_HOME (as the test suite does) moves every cache at once. A
relative XDG_CACHE_HOME is ignored, as the XDG base directory specification says.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

NETS = "nets"
POLICIES = "policies"
TOWNS = "towns"
LOCKS = "locks"


def cache_root() -> Path:
    """$XDG_CACHE_HOME/trustroute when XDG_CACHE_HOME is an absolute path, else ~/.cache/trustroute."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".cache"
    return root / "trustroute"


def cache_dir(kind: str) -> Path:
    """The cache folder of one kind of artefact (NETS, POLICIES, TOWNS) under the cache root."""
    return cache_root() / kind


def entry_lock_path(entry: Path) -> Path:
    """The lock file of a cache entry (networks/sumo_net.py builds under it). Beside the entry in
    trustroute's own cache; for an entry in a folder the user named (`net build --out DIR`), under
    the cache root's `locks/`, named by the entry's absolute path, so that folder holds the entries
    only. Lock files stay where they are: removing one would let a process that still waits on it
    and a new one build the entry at once. Beside the entry, too, when the cache root cannot be
    written (a read-only home is why a user names another folder)."""
    entry = Path(entry).resolve()
    beside = entry.with_name(entry.name + ".lock")
    if entry.is_relative_to(cache_root().resolve()):
        return beside
    locks = cache_root() / LOCKS
    try:
        locks.mkdir(parents=True, exist_ok=True)
    except OSError:
        return beside
    return locks / f"{hashlib.sha256(str(entry).encode()).hexdigest()[:32]}-{entry.name}.lock"
