"""The report's route map on Town01 and on a city-sized town: roads along their shapes, y up."""

from __future__ import annotations

import numpy as np
import pandas as pd

from trustroute.analysis.study.plots import route_plot
from trustroute.networks.town import town_from_dict
from trustroute.policies.logic.spec import load_spec, spec_from_text


def _grid(n: int, spacing: float) -> dict:
    junctions = {f"J{i}_{j}": [i * spacing, j * spacing] for i in range(n) for j in range(n)}
    roads = [[f"J{i}_{j}", f"J{i + 1}_{j}"] for i in range(n - 1) for j in range(n)]
    roads += [[f"J{i}_{j}", f"J{i}_{j + 1}"] for i in range(n) for j in range(n - 1)]
    incidents = {f"{u}-{v}": "truck" if (i % 7) == 0 else "none"
                 for i, (a, b) in enumerate(roads) for u, v in ((a, b), (b, a))}
    return {"junctions": junctions, "roads": roads, "incidents": incidents}


def _episodes(route: list[str], spec: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    episodes = pd.DataFrame({"episode_id": ["e1"], "spec": [spec], "condition": ["aware"]})
    roads = pd.DataFrame({"episode_id": ["e1"] * len(route), "index": range(len(route)),
                          "directed_road": route})
    return roads, episodes


def _drawn_lines(monkeypatch) -> list[np.ndarray]:
    """Every polyline the route map draws (matplotlib's Axes.plot recorded)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.axes import Axes

    lines: list[np.ndarray] = []
    plot = Axes.plot

    def record(self, *args, **kwargs):
        lines.append(np.column_stack([np.asarray(args[0], float), np.asarray(args[1], float)]))
        return plot(self, *args, **kwargs)

    monkeypatch.setattr(Axes, "plot", record)
    return lines


def test_a_city_sized_town_is_drawn_along_its_shapes(tmp_path, monkeypatch):
    data = _grid(10, 200.0)
    bend = [[0.0, 0.0], [100.0, -60.0], [200.0, 0.0]]
    data["geometry"] = {"J0_0-J1_0": {"shape": bend}, "J1_0-J0_0": {"shape": bend[::-1]}}
    town = town_from_dict(data, "city.json")
    text = 'name = "c"\nstart = "J0_0-J1_0"\nformula = "F v"\n[states]\nv = {junction = "J5_5"}\n'
    spec = spec_from_text(text, "c.toml", town)
    roads, episodes = _episodes(["J0_0-J1_0", "J1_0-J2_0", "J2_0-J2_1"], "c")
    lines = _drawn_lines(monkeypatch)
    path = route_plot(town, roads, episodes, tmp_path / "routes.png", {"c": spec})
    assert path.stat().st_size > 10_000
    assert any(len(line) == 3 and np.allclose(line, bend) for line in lines)  # the bent road's course
    assert sum(len(line) == 2 for line in lines) >= len(town.roads) - 1  # the others straight


def test_town01_route_map(town, tmp_path, monkeypatch):
    spec = load_spec("specs/phi1.toml", town)
    roads, episodes = _episodes(["E-A", "A-F", "F-G", "G-I"], "phi1")
    lines = _drawn_lines(monkeypatch)
    path = route_plot(town, roads, episodes, tmp_path / "routes.png", {"phi1": spec})
    assert path.stat().st_size > 10_000
    drawn = {tuple(map(tuple, line)) for line in lines}
    for u, v in town.roads:
        assert any(line[0] in ((*town.junctions[u],), (*town.junctions[v],)) for line in drawn), (u, v)
    assert len(lines) >= len(town.roads) + 3  # every road, and the three driven ones again
