"""Plots of a study (matplotlib, Agg backend: no display needed), each written to a PNG file.

satisfaction_plot   satisfaction rate per spec and condition with bootstrap CIs, the policy's
                    exact value and the synthesized [lower, upper] beside it
trust_plot          mean reported (solid) and true (dashed) trust against the road index,
                    per spec, one line per condition
route_plot          how often each road was driven, on the town map, per spec and condition
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from trustroute.analysis.dataset import PLOTS_DIR
from trustroute.networks.town import Town, split_road

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def satisfaction_plot(cells: list[dict], path: Path, belief_source: str) -> Path:
    plt = _pyplot()
    specs = list(dict.fromkeys(c["spec"] for c in cells))
    conditions = list(dict.fromkeys(c["condition"] for c in cells))
    width = 0.8 / max(1, len(conditions))
    fig, ax = plt.subplots(figsize=(1.8 + 2.2 * len(specs), 3.6))
    for j, condition in enumerate(conditions):
        for i, spec in enumerate(specs):
            cell = next((c for c in cells if c["spec"] == spec and c["condition"] == condition), None)
            if cell is None or cell["satisfaction_rate"] is None:
                continue
            x = i + (j - (len(conditions) - 1) / 2) * width
            rate = cell["satisfaction_rate"]
            ax.bar(
                x,
                rate,
                width * 0.9,
                color=COLOURS[j % len(COLOURS)],
                alpha=0.8,
                label=condition if i == 0 else None,
            )
            if cell["ci_low"] is not None:
                ax.errorbar(
                    x,
                    rate,
                    yerr=[[rate - cell["ci_low"]], [cell["ci_high"] - rate]],
                    color="black",
                    capsize=4,
                    lw=1,
                )
            if cell.get("exact_lower") is not None:
                ax.plot(
                    [x - width * 0.4, x + width * 0.4],
                    [cell["exact_lower"]] * 2,
                    color="black",
                    ls="--",
                    lw=1.2,
                    label="exact value (nominal driver)" if i == 0 and j == 0 else None,
                )
            if cell.get("synthesized_lower") is not None:
                ax.fill_between(
                    [x - width * 0.45, x + width * 0.45],
                    cell["synthesized_lower"],
                    max(cell["synthesized_upper"], cell["synthesized_lower"] + 0.004),
                    color="orange",
                    alpha=0.6,
                    label="synthesized [L, U] (its own objective)" if i == 0 and j == 0 else None,
                )
    ax.set_xticks(range(len(specs)), specs)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("satisfaction rate")
    ax.set_title(f"Spec satisfaction (beliefs: {belief_source}), 95% bootstrap CI", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def trust_plot(roads: pd.DataFrame, episodes: pd.DataFrame, path: Path, max_index: int = 30) -> Path:
    plt = _pyplot()
    merged = roads[["episode_id", "index", "trust_after", "reported_trust"]].merge(
        episodes[["episode_id", "spec", "condition"]], on="episode_id"
    )
    merged = merged[merged["index"] <= max_index]
    specs = list(dict.fromkeys(episodes["spec"]))
    fig, axes = plt.subplots(1, max(1, len(specs)), figsize=(4.2 * max(1, len(specs)), 3.4), squeeze=False)
    for ax, spec in zip(axes[0], specs, strict=False):
        for j, condition in enumerate(dict.fromkeys(episodes["condition"])):
            group = merged[(merged["spec"] == spec) & (merged["condition"] == condition)]
            if group.empty:
                continue
            colour = COLOURS[j % len(COLOURS)]
            # Only indices where enough episodes are still running: a mean of two episodes is noise.
            running = group.groupby("index").size()
            enough = running.index[running >= max(3, 0.02 * running.iloc[0])]
            true = group.groupby("index")["trust_after"].mean().loc[enough]
            reported = group[group["reported_trust"].notna()].groupby("index")["reported_trust"].mean()
            reported = reported.loc[reported.index.isin(enough)]
            ax.plot(reported.index, reported.values, color=colour, label=f"{condition} reported")
            ax.plot(true.index, true.values, color=colour, ls="--", lw=1, label=f"{condition} true")
        ax.set_title(spec, fontsize=10)
        ax.set_xlabel("road index (junctions driven)")
        ax.set_ylim(1, 7)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("mean trust (Muir 1-7)")
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Trust along the episodes (mean over episodes still running, >= 2% of them)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def route_plot(town: Town, roads: pd.DataFrame, episodes: pd.DataFrame, path: Path) -> Path:
    """Line width and colour: the share of episodes that drove each road (either direction)."""
    plt = _pyplot()
    specs = list(dict.fromkeys(episodes["spec"]))
    conditions = list(dict.fromkeys(episodes["condition"]))
    merged = roads[["episode_id", "index", "directed_road"]].merge(
        episodes[["episode_id", "spec", "condition"]], on="episode_id"
    )
    merged = merged[merged["index"] > 0]
    fig, axes = plt.subplots(
        len(specs) or 1,
        len(conditions) or 1,
        figsize=(3.3 * max(1, len(conditions)), 3.3 * max(1, len(specs))),
        squeeze=False,
    )
    xy = town.junctions
    for i, spec in enumerate(specs):
        for j, condition in enumerate(conditions):
            ax = axes[i][j]
            group = merged[(merged["spec"] == spec) & (merged["condition"] == condition)]
            count = episodes[(episodes["spec"] == spec) & (episodes["condition"] == condition)].shape[0]
            undirected = group.assign(
                road=group["directed_road"].map(lambda r: "-".join(sorted(split_road(r))))
            )
            share = undirected.drop_duplicates(["episode_id", "road"]).groupby("road").size() / max(1, count)
            for u, v in town.roads:
                key = "-".join(sorted((u, v)))
                s = float(share.get(key, 0.0))
                (x1, y1), (x2, y2) = xy[u], xy[v]
                ax.plot([x1, x2], [y1, y2], color="lightgrey", lw=1, zorder=1)
                if s > 0:
                    ax.plot(
                        [x1, x2],
                        [y1, y2],
                        color=plt.cm.viridis(s),
                        lw=1 + 7 * s,
                        zorder=2,
                        solid_capstyle="round",
                    )
            for name, (x, y) in xy.items():
                ax.scatter([x], [y], s=60, color="white", edgecolor="black", zorder=3)
                ax.text(x, y, name, ha="center", va="center", fontsize=6, zorder=4)
            ax.set_title(f"{spec} / {condition} (n={count})", fontsize=9)
            ax.set_aspect("equal")
            ax.axis("off")
    fig.suptitle("Share of episodes driving each road", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_plots(
    study_dir: Path,
    town: Town,
    cells: list[dict],
    roads: pd.DataFrame,
    episodes: pd.DataFrame,
    belief_source: str,
) -> dict[str, Path]:
    folder = Path(study_dir) / PLOTS_DIR
    folder.mkdir(parents=True, exist_ok=True)
    return {
        "satisfaction": satisfaction_plot(cells, folder / "satisfaction.png", belief_source),
        "trust": trust_plot(roads, episodes, folder / "trust.png"),
        "routes": route_plot(town, roads, episodes, folder / "routes.png"),
    }
