"""Figures fit for a paper: a vector file beside every PNG, PNGs at PNG_DPI, trust bands only where
enough episodes report."""

from __future__ import annotations

from pathlib import Path

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


@pytest.mark.slow
def test_every_plot_has_a_vector_file_and_a_print_resolution(model_report):
    """The plots of the model study's report (tests/conftest.py, `model_report`)."""
    plots = {path.stem: path for path in Path(model_report["paths"]["plots"]).glob("*.png")}
    assert set(plots) >= {"satisfaction", "trust", "routes", "takeovers", "participants"}
    assert PNG_DPI >= 200
    for path in plots.values():
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


def test_a_participants_panel_says_how_many_drove_every_condition(tmp_path, monkeypatch):
    """A participant without an episode of a condition (a log the authors did not release) is a
    lone point, not a pair: the panel's n says how many of its participants are pairs."""
    from trustroute.analysis.study import plots

    figures = []
    real = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path, **kw: figures.append(fig) or real(fig, path, **kw))
    rows = pd.DataFrame({"participant": range(4), "spec": ["phi2"] * 4, "trust_aware": [5.0, 6, np.nan, 3],
                         "trust_free": [4.0, 6, 5, 3], "satisfied_aware": [True, True, None, False],
                         "satisfied_free": [True, False, True, True]})
    plots.paired_plot(rows, ("aware", "free"), tmp_path / "participants.png")
    plots.paired_plot(rows.iloc[[0, 1, 3]], ("aware", "free"), tmp_path / "paired.png")
    assert [fig.axes[0].get_title() for fig in figures] == ["phi2 (n=4, 3 with every condition)",
                                                            "phi2 (n=3)"]


def _trust_notes(tmp_path, monkeypatch, cells: dict[str, pd.DataFrame]) -> list[str]:
    """The notes under the spec's name in the title of `trust_plot`'s panel of one spec whose
    conditions' roads are `cells` (condition: `_cell` rows)."""
    return _trust_panel(tmp_path, monkeypatch, cells).get_title().splitlines()[1:]


def _trust_panel(tmp_path, monkeypatch, cells: dict[str, pd.DataFrame]):
    """`trust_plot`'s panel (axes) of one spec whose conditions' roads are `cells`."""
    from trustroute.analysis.study import plots

    figures = []
    real = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path, **kw: figures.append(fig) or real(fig, path, **kw))
    roads = pd.concat([cell.assign(episode_id=lambda f, c=condition: c + "-" + f["episode_id"])
                       for condition, cell in cells.items()])
    roads = roads.rename(columns={"reported": "reported_trust"})
    episodes = pd.DataFrame({"episode_id": list(dict.fromkeys(roads["episode_id"])), "spec": "drt"})
    episodes["condition"] = episodes["episode_id"].str.split("-").str[0]
    plots.trust_plot(roads, episodes, tmp_path / "trust.png")
    (fig,) = figures
    return fig.axes[0]


def test_a_trust_panel_without_a_mean_says_why(tmp_path, monkeypatch):
    notes = _trust_notes(tmp_path, monkeypatch, {"aware": _cell(MIN_LINE_EPISODES - 1),
                                                 "free": _cell(MIN_LINE_EPISODES)})
    assert notes == [f"aware: no mean (< {MIN_LINE_EPISODES} episodes at every index)",
                     f"free: no band (< {MIN_BAND_EPISODES} reports per index)"]


def test_a_trust_panel_of_enough_episodes_without_reports_says_none_reported(tmp_path, monkeypatch):
    silent = _cell(MIN_BAND_EPISODES + 2).assign(reported=np.nan)
    notes = _trust_notes(tmp_path, monkeypatch, {"aware": silent, "free": _cell(MIN_BAND_EPISODES + 2)})
    assert notes == ["aware: no mean (no trust reports)", f"free: band on {MIN_BAND_EPISODES + 2} episodes"]


def test_a_trust_panel_draws_no_true_trust_where_none_is_known(tmp_path, monkeypatch):
    """People's hidden trust is unknown (an imported or live study: `trust_after` null): the legend
    offers no "true" line that the panel cannot draw; a simulated cell still has one."""
    hidden = _cell(MIN_BAND_EPISODES + 2).assign(trust_after=None)
    panel = _trust_panel(tmp_path, monkeypatch, {"aware": hidden, "free": _cell(MIN_BAND_EPISODES + 2)})
    labels = [line.get_label() for line in panel.get_lines()]
    assert labels == ["aware reported (mean, 95% CI: mean ± 1.96 SE, normal approx.)",
                      "free reported (mean, 95% CI: mean ± 1.96 SE, normal approx.)", "free true"]


def test_a_plot_interrupted_while_it_is_saved_leaves_the_old_file(tmp_path, monkeypatch):
    """Ctrl-C half-way through matplotlib's write: the plot file is the old one, whole, and nothing
    else is left beside it."""
    from matplotlib.figure import Figure

    def half_written(self, fname, **options):
        if isinstance(fname, (str, Path)):
            with open(fname, "wb") as handle:
                handle.write(b"half a PNG")
        else:
            fname.write(b"half a PNG")
        raise KeyboardInterrupt

    path = tmp_path / "trust.png"
    path.write_bytes(b"the old plot")
    monkeypatch.setattr(Figure, "savefig", half_written)
    with pytest.raises(KeyboardInterrupt):
        _trust_notes(tmp_path, monkeypatch, {"aware": _cell(MIN_BAND_EPISODES)})
    assert path.read_bytes() == b"the old plot"
    assert [p.name for p in tmp_path.iterdir()] == ["trust.png"]


def test_the_satisfaction_plot_gives_each_bars_n_and_marks_a_fallback_only_condition(tmp_path, monkeypatch):
    """A reader of the figure alone sees how many episodes each rate rests on and which condition
    measured only its fallback (the cells table's mark, docs/study.md)."""
    from trustroute.analysis.study import plots
    from trustroute.analysis.study.display import FALLBACK_MARK

    figures = []
    real = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, path, **kw: figures.append(fig) or real(fig, path, **kw))
    cells = pd.DataFrame({"spec": ["phi1", "phi1", "phi2", "phi2"], "condition": ["aware", "free"] * 2,
                          "n": [21, 21, 20, 19], "satisfaction_rate": [0.9, 0.8, 0.7, 0.6],
                          "ci_low": [0.7, 0.6, 0.5, 0.4], "ci_high": [1.0, 0.9, 0.85, 0.8],
                          "fallback_only": [True, False, False, False]})
    plots.satisfaction_plot(cells, tmp_path / "satisfaction.png", "true")
    (fig,) = figures
    (ax,) = fig.axes
    texts = [t.get_text() for t in ax.texts]
    assert sorted(t for t in texts if t.startswith("n=")) == ["n=19", "n=20", "n=21", "n=21"]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(FALLBACK_MARK.strip() in label for label in labels), labels
    hatched = [p for p in ax.patches if p.get_hatch()]
    assert len(hatched) == 1 and hatched[0].get_height() == pytest.approx(0.9)


def test_the_trust_plots_road_index_has_whole_ticks(tmp_path, monkeypatch):
    """A road index is a count of junctions: no tick between two roads (2.5, 7.5), whatever the
    episodes' length."""
    rng = np.random.default_rng(2)
    long = pd.DataFrame([{"episode_id": f"e{e}", "index": i, "trust_after": int(rng.integers(1, 8)),
                          "reported": float(rng.integers(1, 8))} for e in range(12) for i in range(14)])
    panel = _trust_panel(tmp_path, monkeypatch, {"aware": long})
    ticks = [t for t in panel.get_xticks() if panel.get_xlim()[0] <= t <= panel.get_xlim()[1]]
    assert len(ticks) > 1 and all(float(t).is_integer() for t in ticks), ticks
