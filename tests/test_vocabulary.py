"""One vocabulary across the package, read with `ast`: a road id "U-V" is taken apart only by
`networks/road.py`'s `Road`."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.test_architecture import REPO, package_modules

ROAD_MODULE = "trustroute.networks.road"
SPLITTERS = {"split", "rsplit", "partition", "rpartition"}


def hand_splits(source: str, filename: str) -> list[int]:
    """Lines that split a string on "-" (`x.split("-")`, `x.partition("-")`, ...)."""
    return [node.lineno for node in ast.walk(ast.parse(source, filename))
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
            and node.func.attr in SPLITTERS and node.args
            and isinstance(node.args[0], ast.Constant) and node.args[0].value == "-"]


def road_splits_outside_road(modules: dict[str, Path], extra: dict[str, str] | None = None) -> list[str]:
    sources = {module: path.read_text() for module, path in modules.items()}
    sources.update(extra or {})
    return [f"{module}:{line}" for module, source in sorted(sources.items()) if module != ROAD_MODULE
            for line in hand_splits(source, module)]


def test_only_road_splits_road_ids():
    assert road_splits_outside_road(package_modules()) == []


def test_a_hand_split_is_caught():
    added = {"trustroute.networks.town": (REPO / "networks" / "town.py").read_text()
             + "\n\ndef arrived(road):\n    return road.split('-')[1]\n",
             "trustroute.harness.live.view": "u, _, v = road.rpartition(\"-\")\n"}
    found = road_splits_outside_road(package_modules(), added)
    assert [f.split(":")[0] for f in found] == ["trustroute.harness.live.view", "trustroute.networks.town"]
