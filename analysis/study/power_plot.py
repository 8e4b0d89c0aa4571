"""The power curve of `trustroute plan`: per planned test (one panel each) the estimated power
against the number of participants, one line per (pair, spec) with its Wilson 95 % band, the
target power as a dashed line and the minimal sample size reaching it marked; PNG and SVG. A plan
from a pilot adds, per line, the range of its refits' powers as thin dash-dotted lines."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from trustroute.analysis.study.plots import COLOURS, PNG_DPI, save_figure, vector_path
from trustroute.analysis.study.power import TESTS, Power, minimal_sizes


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def power_curve_plot(table: Sequence[Power], target: float, alpha: float, path: Path,
                     title: str = "") -> Path:
    fig = power_curve_figure(table, target, alpha, title)
    save_figure(fig, path, dpi=PNG_DPI)
    save_figure(fig, vector_path(path))
    _pyplot().close(fig)
    return Path(path)


def power_curve_figure(table: Sequence[Power], target: float, alpha: float, title: str = ""):
    """The figure of `power_curve_plot`, unsaved. Sample sizes are whole participants: the
    x axis ticks only integers (a plan of one or two sizes would otherwise read 7.6, 7.8, ...)."""
    from matplotlib.ticker import MaxNLocator

    plt = _pyplot()
    tests = list(dict.fromkeys(p.test for p in table))
    minimal = minimal_sizes(table, target)
    fig, axes = plt.subplots(1, len(tests), figsize=(4.2 * len(tests), 3.8), squeeze=False, sharey=True)
    for ax, test in zip(axes[0], tests, strict=True):
        keys = list(dict.fromkeys((p.pair, p.spec) for p in table if p.test == test))
        for k, (pair, spec) in enumerate(keys):
            rows = sorted((p for p in table if p.test == test and (p.pair, p.spec) == (pair, spec)),
                          key=lambda p: p.participants)
            sizes = [p.participants for p in rows]
            colour = COLOURS[k % len(COLOURS)]
            label = f"{spec}" + (f" ({pair[0]} vs {pair[1]})" if len({q for q, _ in keys}) > 1 else "")
            ax.fill_between(sizes, [p.low for p in rows], [p.high for p in rows], color=colour, alpha=0.2,
                            lw=0)
            if any(p.models for p in rows):   # a pilot's refits: the power's range over the fit
                ax.plot(sizes, [p.fit_low for p in rows], color=colour, ls="-.", lw=0.8)
                ax.plot(sizes, [p.fit_high for p in rows], color=colour, ls="-.", lw=0.8)
            ax.plot(sizes, [p.power for p in rows], marker="o", ms=3, color=colour, label=label)
            found = minimal[(test, pair, spec)]
            if found is not None:
                ax.axvline(found, color=colour, ls=":", lw=1)
                ax.annotate(f"N={found}", (found, 0.03 + 0.07 * k), color=colour, fontsize=7,
                            xytext=(3, 0), textcoords="offset points")
        ax.axhline(target, color="black", ls="--", lw=1)
        ax.axhline(alpha, color="grey", ls=":", lw=0.8)   # the power of a test where there is no effect
        ax.annotate(f"α = {alpha:g}", (1.0, alpha), xycoords=("axes fraction", "data"), color="grey",
                    fontsize=7, ha="right", va="bottom", xytext=(-3, 1), textcoords="offset points")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
        ax.set_ylim(0, 1.02)
        ax.set_title(TESTS[test], fontsize=9)
        ax.set_xlabel("participants")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", frameon=False)  # power curves rise: that corner is empty
    axes[0][0].set_ylabel(f"power at α = {alpha:g} (95% interval)")
    fig.suptitle(title or f"Power by simulation (dashed: target {target:g}; dotted: minimal N)", fontsize=9)
    fig.tight_layout()
    return fig
