"""Figures fit for a paper: a vector file beside every PNG, PNGs at PNG_DPI, trust bands only where
enough episodes report."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from trustroute.analysis.study.plots import (
    MIN_BAND_EPISODES,
    MIN_LINE_EPISODES,
    PNG_DPI,
    trust_series,
    vector_path,
)
from trustroute.analysis.study.report import write_report


@pytest.mark.slow
def test_every_plot_has_a_vector_file_and_a_print_resolution(model_study):
    paths = write_report(model_study)
    assert set(paths.plots) >= {"satisfaction", "trust", "routes", "takeovers", "participants"}
    assert PNG_DPI >= 200
    for path in paths.plots.values():
        svg = vector_path(path)
        assert svg.is_file() and svg.read_text().lstrip().startswith("<?xml") and "<svg" in svg.read_text()
        with Image.open(path) as image:
            assert round(image.info["dpi"][0]) >= PNG_DPI


def _cell(episodes: int, reports_every: int = 1) -> pd.DataFrame:
    rng = np.random.default_rng(1)
    rows = [{"episode_id": f"e{e}", "index": i, "trust_after": int(rng.integers(1, 8)),
             "reported": float(rng.integers(1, 8)) if i % reports_every == 0 else np.nan}
            for e in range(episodes) for i in range(6)]
    return pd.DataFrame(rows)


def test_trust_bands_rest_on_enough_episodes():
    true, stats, band = trust_series(_cell(3))
    assert stats.empty and true.empty and band.empty  # 3 episodes: nothing drawn
    true, stats, band = trust_series(_cell(MIN_LINE_EPISODES))
    assert len(stats) == 6 and len(true) == 6 and band.empty  # means, but no band
    true, stats, band = trust_series(_cell(MIN_BAND_EPISODES + 2))
    assert len(band) == 6 and (band["count"] >= MIN_BAND_EPISODES).all()
    assert np.allclose((band["low"] + band["high"]) / 2, stats["mean"])


def test_the_participants_title_fits_a_plot_of_one_spec(tmp_path, monkeypatch):
    from trustroute.analysis.study import plots

    figures = []
    real = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path, **kw: figures.append(fig) or real(fig, path, **kw))
    one_spec = pd.DataFrame({"participant": range(4), "spec": ["drt"] * 4, "trust_aware": [5.0, 6, 4, 3],
                             "trust_free": [4.0, 6, 5, 3], "satisfied_aware": [True] * 4,
                             "satisfied_free": [True, False, True, True]})
    plots.paired_plot(one_spec, ("aware", "free"), tmp_path / "participants.png", belief_source="true")
    (fig,) = figures
    title = fig.get_suptitle()
    assert "green = higher under aware" in title.replace("\n", " ")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    box = fig._suptitle.get_window_extent(FigureCanvasAgg(fig).get_renderer())  # as saved
    assert 0 <= box.x0 and box.x1 <= fig.bbox.width and 0 <= box.y0 and box.y1 <= fig.bbox.height


def test_a_trust_panel_without_a_mean_says_why(tmp_path, monkeypatch):
    from trustroute.analysis.study import plots

    figures = []
    real = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path, **kw: figures.append(fig) or real(fig, path, **kw))
    roads = pd.concat([_cell(MIN_LINE_EPISODES - 1).assign(episode_id=lambda f: "a" + f["episode_id"]),
                       _cell(MIN_LINE_EPISODES).assign(episode_id=lambda f: "f" + f["episode_id"])])
    roads = roads.rename(columns={"reported": "reported_trust"})
    episodes = pd.DataFrame({"episode_id": sorted(set(roads["episode_id"])), "spec": "drt"})
    episodes["condition"] = np.where(episodes["episode_id"].str.startswith("a"), "aware", "free")
    plots.trust_plot(roads, episodes, tmp_path / "trust.png")
    (fig,) = figures
    notes = fig.axes[0].get_title().splitlines()
    assert notes[1] == f"aware: no mean (< {MIN_LINE_EPISODES} episodes at every index)"
    assert notes[2] == f"free: no band (< {MIN_BAND_EPISODES} reports per index)"
