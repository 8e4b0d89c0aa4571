"""The one cache root of trustroute: `$XDG_CACHE_HOME/trustroute`, default `~/.cache/trustroute`.

Built SUMO nets (`nets/`, networks/sumo_net.py), synthesized "aware" policies (`policies/`,
policies/resolve.py) and the towns imported on first use (`towns/`, networks/cities.py) live
under it. The root is read when a cache path is asked for, not
at import, so setting XDG_CACHE_HOME (as the test suite does) moves every cache at once. A
relative XDG_CACHE_HOME is ignored, as the XDG base directory specification says.
"""

from __future__ import annotations

import os
from pathlib import Path

NETS = "nets"
POLICIES = "policies"
TOWNS = "towns"


def cache_root() -> Path:
    """$XDG_CACHE_HOME/trustroute when XDG_CACHE_HOME is an absolute path, else ~/.cache/trustroute."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".cache"
    return root / "trustroute"


def cache_dir(kind: str) -> Path:
    """The cache folder of one kind of artefact (NETS, POLICIES, TOWNS) under the cache root."""
    return cache_root() / kind
