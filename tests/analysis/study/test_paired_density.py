"""paired_plot above MAX_PAIRED_LINES participants in a spec draws their density, not one line each."""

from __future__ import annotations

import numpy as np
import pandas as pd

from trustroute.analysis.study import plots


def _participants(n: int) -> pd.DataFrame:
    rng = np.random.default_rng(3)
    return pd.DataFrame({
        "participant": np.tile(np.arange(n), 2), "spec": ["phi1"] * n + ["phi2"] * n,
        "trust_aware": rng.integers(1, 8, 2 * n).astype(float), "trust_free": rng.integers(1, 8, 2 * n) / 1.0,
        "satisfied_aware": rng.random(2 * n) < 0.9, "satisfied_free": rng.random(2 * n) < 0.7})


def test_many_participants_are_drawn_as_a_density(tmp_path, monkeypatch):
    calls = []
    real = plots.paired_density_plot
    monkeypatch.setattr(plots, "paired_density_plot", lambda *a: calls.append(a) or real(*a))
    few = plots.paired_plot(_participants(12), ("aware", "free"), tmp_path / "few.png")
    assert few.exists() and not calls
    many = plots.paired_plot(_participants(plots.MAX_PAIRED_LINES + 1), ("aware", "free"),
                             tmp_path / "many.png")
    assert many.exists() and plots.vector_path(many).exists() and len(calls) == 1
