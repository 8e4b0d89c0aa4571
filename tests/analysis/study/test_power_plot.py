"""The power curve of `trustroute plan` reads as what it plots: whole participants on the x axis,
and every line it draws named (the dashed target and the dotted minimal N in the title, the grey
dotted α on its line)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import pytest

from trustroute.analysis.study.power import Power
from trustroute.analysis.study.power_plot import power_curve_figure


def _row(participants: int, power: float) -> Power:
    return Power(test="mcnemar", pair=("aware", "free"), spec="phi1", participants=participants, studies=20,
                 rejected=round(20 * power), power=power, low=max(power - 0.1, 0.0),
                 high=min(power + 0.1, 1.0), effect_median=0.1, effect_low=0.0, effect_high=0.3)


@pytest.mark.parametrize("sizes", [(8,), (8, 12), (8, 12, 16, 20, 24, 28, 32, 36, 40)])
def test_the_x_axis_ticks_whole_participants(sizes):
    figure = power_curve_figure([_row(n, 0.1) for n in sizes], target=0.8, alpha=0.05)
    try:
        ticks = figure.axes[0].get_xticks()
        low, high = figure.axes[0].get_xlim()
        shown = [tick for tick in ticks if low <= tick <= high]
        assert shown and all(float(tick).is_integer() for tick in shown), shown
    finally:
        plt.close(figure)


def test_the_alpha_line_is_named_on_every_panel():
    rows = [_row(8, 0.1), _row(12, 0.3)]
    rows += [Power(**{**vars(row), "test": "wilcoxon"}) for row in rows]
    figure = power_curve_figure(rows, target=0.8, alpha=0.05)
    try:
        assert len(figure.axes) == 2
        for ax in figure.axes:
            assert "α = 0.05" in [text.get_text() for text in ax.texts]
    finally:
        plt.close(figure)
