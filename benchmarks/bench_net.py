"""SUMO net build of the default town: first build (netconvert) vs a cache hit."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from benchmarks.timing import best_seconds
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import load_town


def run() -> list[dict]:
    town = load_town()
    firsts = []
    for _ in range(3):
        with tempfile.TemporaryDirectory() as directory:
            started = time.perf_counter()
            build_net(town, cache_dir=Path(directory))
            firsts.append(time.perf_counter() - started)
    with tempfile.TemporaryDirectory() as directory:
        build_net(town, cache_dir=Path(directory))
        cached = best_seconds(lambda: build_net(town, cache_dir=Path(directory)), repeats=20)
    first = min(firsts)
    return [
        {"name": "net_build_first", "value": first, "unit": "s"},
        {"name": "net_build_cached", "value": cached, "unit": "s", "baseline": first,
         "ratio": cached / first},
    ]
