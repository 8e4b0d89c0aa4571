"""Plots of a study (matplotlib, Agg backend: no display needed), each written to a PNG file.

satisfaction_plot   satisfaction rate per spec and condition with exact (Clopper–Pearson) 95 %
                    intervals, the policy's exact value and the synthesized [lower, upper] beside it
paired_plot         per participant, mean reported trust under each condition joined by a line
                    (one panel per spec), satisfied episodes filled
trust_plot          mean reported and true trust against the road index, per spec and condition,
                    with a 95 % band of the mean of reported trust (normal approximation)
route_plot          share of episodes driving each road on the town map (colour bar), with the
                    spec's start road, its waypoint roads and the incident types marked; roads
                    along their courses, offsets and markers scaled to the town (networks/town_map.py)
takeover_plot       takeover rate per incident type and condition with exact 95 % intervals
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.core.dataset import PLOTS_DIR
from trustroute.networks.road_lookup import road_shape
from trustroute.networks.town import Town, split_road
from trustroute.networks.town_map import map_frame, names_every_junction, point_along

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")
INCIDENT_MARKERS = {"pedestrian": ("P", "#ff8c00"), "obstacle": ("s", "#c8a000"), "truck": ("^", "#5a5aff")}
WAYPOINT_COLOURS = ("#ffb000", "#e377c2", "#17becf", "#bcbd22", "#8c564b")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _pyplot().close(fig)
    return path


def satisfaction_plot(cells: pd.DataFrame, path: Path, belief_source: str) -> Path:
    plt = _pyplot()
    specs = list(dict.fromkeys(cells["spec"])) if len(cells) else []
    conditions = list(dict.fromkeys(cells["condition"])) if len(cells) else []
    width = 0.8 / max(1, len(conditions))
    fig, ax = plt.subplots(figsize=(1.8 + 2.2 * max(1, len(specs)), 3.6))
    for cell in cells.to_dict("records"):
        if cell["satisfaction_rate"] is None or pd.isna(cell["satisfaction_rate"]):
            continue
        i, j = specs.index(cell["spec"]), conditions.index(cell["condition"])
        x = i + (j - (len(conditions) - 1) / 2) * width
        rate = cell["satisfaction_rate"]
        ax.bar(
            x,
            rate,
            width * 0.9,
            color=COLOURS[j % len(COLOURS)],
            alpha=0.8,
            label=cell["condition"] if i == 0 else None,
        )
        ax.errorbar(
            x, rate, yerr=[[rate - cell["ci_low"]], [cell["ci_high"] - rate]], color="black", capsize=4, lw=1
        )
        first = i == 0 and j == 0
        if cell.get("exact_lower") is not None and not pd.isna(cell.get("exact_lower")):
            ax.plot(
                [x - width * 0.4, x + width * 0.4],
                [cell["exact_lower"]] * 2,
                color="black",
                ls="--",
                lw=1.2,
                label="exact value (nominal driver)" if first else None,
            )
        if cell.get("synthesized_lower") is not None and not pd.isna(cell.get("synthesized_lower")):
            ax.fill_between(
                [x - width * 0.45, x + width * 0.45],
                cell["synthesized_lower"],
                max(cell["synthesized_upper"], cell["synthesized_lower"] + 0.004),
                color="orange",
                alpha=0.6,
                label="synthesized [L, U] (its own objective)" if first else None,
            )
    ax.set_xticks(range(len(specs)), specs)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("satisfaction rate")
    ax.set_title(f"Spec satisfaction (beliefs: {belief_source}), exact 95% CI", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    return _save(fig, path)


def paired_plot(per_participant: pd.DataFrame, pair: tuple[str, str], path: Path) -> Path:
    plt = _pyplot()
    a, b = pair
    specs = list(dict.fromkeys(per_participant["spec"])) if len(per_participant) else [""]
    fig, axes = plt.subplots(1, len(specs), figsize=(3.4 * len(specs), 3.6), squeeze=False, sharey=True)
    rng = np.random.default_rng(0)  # jitter only, so overlapping participants stay visible
    for ax, spec in zip(axes[0], specs, strict=True):
        group = per_participant[per_participant["spec"] == spec]
        for row in group.itertuples(index=False):
            ya, yb = getattr(row, f"trust_{a}"), getattr(row, f"trust_{b}")
            jitter = rng.uniform(-0.04, 0.04)
            colour = "#2ca02c" if ya > yb else "#d62728" if ya < yb else "grey"
            ax.plot([0 + jitter, 1 + jitter], [ya, yb], color=colour, alpha=0.6, lw=1)
            for x, y, sat in (
                (0, ya, getattr(row, f"satisfied_{a}")),
                (1, yb, getattr(row, f"satisfied_{b}")),
            ):
                ax.scatter(
                    [x + jitter],
                    [y],
                    s=22,
                    zorder=3,
                    edgecolor="black",
                    linewidth=0.6,
                    color="black" if bool(sat) else "white",
                )
        ax.set_xticks([0, 1], [a, b])
        ax.set_xlim(-0.4, 1.4)
        ax.set_title(f"{spec} (n={len(group)})", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel("participant's mean reported trust")
    fig.suptitle(
        f"Per participant: {a} vs {b} (filled = spec satisfied; green = higher under {a})", fontsize=9
    )
    return _save(fig, path)


def trust_plot(roads: pd.DataFrame, episodes: pd.DataFrame, path: Path, max_index: int = 30) -> Path:
    plt = _pyplot()
    merged = roads[["episode_id", "index", "trust_after", "reported_trust"]].merge(
        episodes[["episode_id", "spec", "condition"]], on="episode_id"
    )
    merged = merged[merged["index"] <= max_index]
    reported = pd.to_numeric(merged["reported_trust"], errors="coerce").astype(float)
    merged = merged.assign(reported=reported.where(reported >= 1))
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
            stats = group.groupby("index")["reported"].agg(["mean", "std", "count"]).loc[enough]
            stats = stats[stats["count"] > 0]
            half = 1.96 * stats["std"].fillna(0) / np.sqrt(stats["count"])
            ax.fill_between(
                stats.index, stats["mean"] - half, stats["mean"] + half, color=colour, alpha=0.2, lw=0
            )
            ax.plot(stats.index, stats["mean"], color=colour, label=f"{condition} reported (95% band)")
            ax.plot(true.index, true.values, color=colour, ls="--", lw=1, label=f"{condition} true")
        ax.set_title(spec, fontsize=10)
        ax.set_xlabel("road index (junctions driven)")
        ax.set_ylim(1, 7)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("mean trust (Muir 1-7)")
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Trust along the episodes (mean over episodes still running, >= 2% of them)", fontsize=10)
    return _save(fig, path)


def _road_xy(town: Town, road: str, fraction: float = 0.5, offset: float = 18.0) -> tuple[float, float]:
    """A point `fraction` along a directed road's course, `offset` metres to its right (its
    driving side)."""
    return point_along(road_shape(town, road), fraction, offset)


def _undirected_shape(town: Town, u: str, v: str) -> np.ndarray:
    """The course of road u–v (its u-v direction, or v-u for a road one-way from v)."""
    road = f"{u}-{v}" if f"{u}-{v}" in town.incidents else f"{v}-{u}"
    return np.asarray(road_shape(town, road), dtype=float)


@dataclass(frozen=True)
class _MapStyle:
    """Offsets in metres (multiples of the town's map unit) and marker areas in points², smaller in
    a town with many roads so that a city stays readable."""

    unit: float
    shrink: float  # 1 on a town of up to 40 directed roads, less on larger ones
    named: bool  # whether every junction's name is written

    @classmethod
    def of(cls, town: Town) -> _MapStyle:
        return cls(unit=map_frame(town).unit, shrink=min(1.0, (40 / len(town.states)) ** 0.5),
                   named=names_every_junction(town))

    def size(self, points2: float) -> float:
        return points2 * self.shrink


def _draw_roads(ax, plt, town: Town, share: pd.Series, style: _MapStyle) -> None:
    """Every road in light grey along its course, those driven coloured and widened by their share."""
    for u, v in town.roads:
        shape = _undirected_shape(town, u, v)
        s = float(share.get("-".join(sorted((u, v))), 0.0))
        ax.plot(shape[:, 0], shape[:, 1], color="lightgrey", lw=1, zorder=1)
        if s > 0:
            ax.plot(shape[:, 0], shape[:, 1], color=plt.cm.viridis(s), lw=1 + 7 * s * style.shrink, zorder=2,
                    solid_capstyle="round", solid_joinstyle="round")


def _draw_spec(ax, town: Town, definition, style: _MapStyle, first: bool) -> None:
    """The spec's waypoint roads (stars beside them) and its start road (a dot, labelled)."""
    for k, (atom, atom_roads) in enumerate(sorted(definition.state_atoms.items())):
        points = np.array([_road_xy(town, r, 0.6, 4 * style.unit) for r in sorted(atom_roads)])
        ax.scatter(points[:, 0], points[:, 1], marker="*", s=style.size(70), zorder=5, edgecolor="black",
                   linewidth=0.4, color=WAYPOINT_COLOURS[k % len(WAYPOINT_COLOURS)],
                   label=f"waypoint {atom}" if first else None)
    sx, sy = _road_xy(town, definition.start, 0.5, 0.0)
    ax.scatter([sx], [sy], marker="o", s=style.size(90), color="#2ca02c", edgecolor="black", zorder=6,
               label="start" if first else None)
    ax.annotate("start", (sx, sy), xytext=(4, 4), textcoords="offset points", fontsize=6)


def _draw_incidents_and_junctions(ax, town: Town, style: _MapStyle, first: bool) -> None:
    for kind, (marker, colour) in INCIDENT_MARKERS.items():
        points = np.array([_road_xy(town, r, 0.35, 3 * style.unit) for r, k in town.incidents.items()
                           if k == kind])
        if len(points):
            ax.scatter(points[:, 0], points[:, 1], marker=marker, s=style.size(18), color=colour, zorder=4,
                       edgecolor="black", linewidth=0.3, label=kind if first else None)
    names = sorted(town.junctions)
    xy = np.array([town.junctions[n] for n in names])
    ax.scatter(xy[:, 0], xy[:, 1], s=60 if style.named else style.size(12), color="white", edgecolor="black",
               linewidth=0.8 if style.named else 0.4, zorder=3)
    if style.named:
        for name, (x, y) in zip(names, xy, strict=True):
            ax.text(x, y, name, ha="center", va="center", fontsize=6, zorder=7)


def route_plot(
    town: Town, roads: pd.DataFrame, episodes: pd.DataFrame, path: Path, specs_by_name: dict | None = None
) -> Path:
    """Line width and colour: the share of episodes that drove each road (either direction), drawn
    along the roads' courses (their geometry where the town has one) with y up, north at the top."""
    plt = _pyplot()
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    specs = list(dict.fromkeys(episodes["spec"]))
    conditions = list(dict.fromkeys(episodes["condition"]))
    merged = roads[["episode_id", "index", "directed_road"]].merge(
        episodes[["episode_id", "spec", "condition"]], on="episode_id"
    )
    merged = merged[merged["index"] > 0]
    frame = map_frame(town)
    aspect = (frame.y_max - frame.y_min + 1.0) / (frame.x_max - frame.x_min + 1.0)
    width = 3.6 if len(town.junctions) <= 40 else 6.0  # inches per panel
    height = width * min(1.5, max(0.5, aspect))
    fig, axes = plt.subplots(
        len(specs) or 1,
        len(conditions) or 1,
        figsize=(width * max(1, len(conditions)) + 1.0, height * max(1, len(specs))),
        squeeze=False,
    )
    style = _MapStyle.of(town)
    for i, spec in enumerate(specs):
        definition = (specs_by_name or {}).get(spec)
        for j, condition in enumerate(conditions):
            ax = axes[i][j]
            first = i == 0 and j == 0
            group = merged[(merged["spec"] == spec) & (merged["condition"] == condition)]
            count = episodes[(episodes["spec"] == spec) & (episodes["condition"] == condition)].shape[0]
            undirected = group.assign(
                road=group["directed_road"].map(lambda r: "-".join(sorted(split_road(r))))
            )
            share = undirected.drop_duplicates(["episode_id", "road"]).groupby("road").size() / max(1, count)
            _draw_roads(ax, plt, town, share, style)
            if definition is not None:
                _draw_spec(ax, town, definition, style, first)
            _draw_incidents_and_junctions(ax, town, style, first)
            ax.set_title(f"{spec} / {condition} (n={count})", fontsize=9)
            ax.set_aspect("equal")
            ax.axis("off")
    handles, labels = axes[0][0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=min(8, len(handles)), fontsize=7, frameon=False)
    bar = fig.colorbar(
        ScalarMappable(norm=Normalize(0, 1), cmap="viridis"), ax=axes.ravel().tolist(), shrink=0.6, pad=0.02
    )
    bar.set_label("share of episodes driving the road", fontsize=8)
    fig.suptitle("Routes driven; start, waypoint roads and incident types marked", fontsize=10)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def takeover_plot(takeovers: pd.DataFrame, path: Path) -> Path:
    plt = _pyplot()
    incidents = list(dict.fromkeys(takeovers["incident"])) if len(takeovers) else []
    conditions = list(dict.fromkeys(takeovers["condition"])) if len(takeovers) else []
    width = 0.8 / max(1, len(conditions))
    fig, ax = plt.subplots(figsize=(1.8 + 1.8 * max(1, len(incidents)), 3.4))
    for row in takeovers.itertuples(index=False):
        i, j = incidents.index(row.incident), conditions.index(row.condition)
        x = i + (j - (len(conditions) - 1) / 2) * width
        ax.bar(
            x,
            row.rate,
            width * 0.9,
            color=COLOURS[j % len(COLOURS)],
            alpha=0.8,
            label=row.condition if i == 0 else None,
        )
        ax.errorbar(
            x,
            row.rate,
            yerr=[[row.rate - row.ci_low], [row.ci_high - row.rate]],
            color="black",
            capsize=4,
            lw=1,
        )
        ax.text(x, 0.02, f"{row.takeovers}/{row.roads}", ha="center", fontsize=6, rotation=90)
    ax.set_xticks(range(len(incidents)), incidents)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("takeover rate")
    ax.set_title("Takeovers per incident met, exact 95% CI", fontsize=10)
    if conditions:
        ax.legend(fontsize=8)
    return _save(fig, path)


def write_plots(
    study_dir: Path, town: Town, analysis, roads: pd.DataFrame, specs_by_name: dict
) -> dict[str, Path]:
    """Every plot of the report into `<study_dir>/plots/`, by name."""
    folder = Path(study_dir) / PLOTS_DIR
    folder.mkdir(parents=True, exist_ok=True)
    episodes = analysis.episodes
    plots = {
        "satisfaction": satisfaction_plot(
            analysis.cells, folder / "satisfaction.png", analysis.belief_source
        ),
        "trust": trust_plot(roads, episodes, folder / "trust.png"),
        "routes": route_plot(town, roads, episodes, folder / "routes.png", specs_by_name),
        "takeovers": takeover_plot(analysis.takeovers, folder / "takeovers.png"),
    }
    if len(analysis.per_participant) and len(analysis.paired):
        first = analysis.paired.iloc[0]
        plots["participants"] = paired_plot(
            analysis.per_participant,
            (first["condition_a"], first["condition_b"]),
            folder / "participants.png",
        )
    return plots
