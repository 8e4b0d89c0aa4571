"""Plots of a study (matplotlib, Agg backend: no display needed), each written as a PNG at
PNG_DPI with an SVG beside it (same name, for papers); legends sit outside the data.

satisfaction_plot   satisfaction rate per spec and condition with exact (Clopper–Pearson) 95 %
                    intervals, each bar's n, the policy's exact value and the synthesized [lower,
                    upper] beside it; a condition whose policy is only its fallback hatched
paired_plot         per participant, mean reported trust under every condition joined by a line
                    (one panel per spec), satisfied episodes filled; above MAX_PAIRED_LINES
                    participants in a spec, lines would hide each other, so it shows the
                    participants' density instead: per pair of conditions a 2-D histogram of
                    (trust under A, under B) with the diagonal, how many lie on each side, and
                    the satisfaction pairs
trust_plot          mean reported and (where known: simulated drivers) true trust against the
                    road index, per spec and condition, with a 95 % band of the mean of reported
                    trust (normal approximation), drawn only at indices with at least
                    MIN_BAND_EPISODES reports, the legend saying
                    how many episodes the band rests on (or that no mean is drawn, and why)
route_plot          share of episodes driving each road on the town map (colour bar), with the
                    spec's start road, its waypoint roads and the incident types marked; roads
                    along their courses, offsets and markers scaled to the town (networks/town_map.py)
takeover_plot       takeover rate per incident type and condition with exact 95 % intervals
"""

from __future__ import annotations

import io
import itertools
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.study.display import FALLBACK_MARK
from trustroute.core.dataset import PLOTS_DIR
from trustroute.core.output_files import atomic_write_bytes
from trustroute.networks.road import Road
from trustroute.networks.road_lookup import road_shape
from trustroute.networks.town import Town
from trustroute.networks.town_map import map_frame, names_every_junction, point_along

COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")
INCIDENT_MARKERS = {"pedestrian": ("P", "#ff8c00"), "obstacle": ("s", "#c8a000"), "truck": ("^", "#5a5aff")}
WAYPOINT_COLOURS = ("#ffb000", "#e377c2", "#17becf", "#bcbd22", "#8c564b")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


PNG_DPI = 200
MIN_BAND_EPISODES = 10  # fewer reports at an index: its 95 % band would be noise across the scale
BAND_LABEL = "95% CI: mean ± 1.96 SE, normal approx."   # how the trust band is computed (trust_series)
MIN_LINE_EPISODES = 5   # fewer episodes still running at an index: no mean drawn there


def vector_path(path: Path) -> Path:
    """The SVG written beside a plot's PNG."""
    return Path(path).with_suffix(".svg")


def save_figure(fig, path: Path, **options) -> Path:
    """`fig` written to `path` in the format its suffix names, atomically (trustroute/core/
    output_files.py): an interrupted or failed save leaves the old file or none, never half of one.
    `options`: savefig's (dpi, bbox_inches)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format=Path(path).suffix.lstrip("."), **options)
    return atomic_write_bytes(path, buffer.getvalue(), "figure", "pass a writable output path")


def _save(fig, path: Path, tight_box: bool = False) -> Path:
    """The PNG at PNG_DPI and the SVG beside it; `tight_box` keeps legends placed outside the axes."""
    box = {"bbox_inches": "tight"} if tight_box else {}
    if not tight_box:
        fig.tight_layout()
    save_figure(fig, path, dpi=PNG_DPI, **box)
    save_figure(fig, vector_path(path), **box)
    _pyplot().close(fig)
    return path


def _suptitle(fig, text: str, fontsize: float) -> None:
    """The figure's title wrapped to the figure's width, which a plot of one spec makes narrower than
    the title (a character is taken as 0.6 of the font size: above DejaVu Sans' mean width, about 0.5
    on such a title, though its widest letters, m and W, are wider)."""
    fig.suptitle(textwrap.fill(text, max(20, int(fig.get_figwidth() * 72 / (0.6 * fontsize)))),
                 fontsize=fontsize)


def _legend_outside(ax) -> None:
    """The legend right of the axes, where it covers no data."""
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, frameon=False)


def satisfaction_plot(cells: pd.DataFrame, path: Path, belief_source: str) -> Path:
    plt = _pyplot()
    specs = list(dict.fromkeys(cells["spec"])) if len(cells) else []
    conditions = list(dict.fromkeys(cells["condition"])) if len(cells) else []
    width = 0.8 / max(1, len(conditions))
    fig, ax = plt.subplots(figsize=(1.8 + 2.2 * max(1, len(specs)), 3.6))
    fallback_shown = False
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
        ax.text(x, 0.01, f"n={cell['n']}", ha="center", va="bottom", fontsize=7, zorder=6,
                bbox={"facecolor": "white", "edgecolor": "none", "pad": 1.0, "alpha": 0.8})
        if bool(cell.get("fallback_only")):
            # the cells table's mark: this rate measures the fallback, not a synthesized policy
            ax.bar(x, rate, width * 0.9, fill=False, hatch="//", edgecolor="black", lw=0,
                   label=None if fallback_shown else f"hatched:{FALLBACK_MARK}")
            fallback_shown = True
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
            # beside the bar, as a range with end caps and end markers, so that [L, U] shows even
            # when L = U (a certified optimum)
            low, high = cell["synthesized_lower"], cell["synthesized_upper"]
            ax.errorbar(x + width * 0.3, (low + high) / 2, yerr=[[(high - low) / 2], [(high - low) / 2]],
                        color="#ff7f0e", lw=2.5, capsize=5, capthick=2, zorder=4,
                        label="synthesized [L, U] (its own objective)" if first else None)
            ax.scatter([x + width * 0.3] * 2, [low, high], marker="D", s=16, color="#ff7f0e",
                       edgecolor="black", linewidth=0.5, zorder=5)
    ax.set_xticks(range(len(specs)), specs)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("satisfaction rate")
    ax.set_title(f"Spec satisfaction (beliefs: {belief_source}), exact 95% CI", fontsize=10)
    _legend_outside(ax)
    return _save(fig, path, tight_box=True)


MAX_PAIRED_LINES = 300  # participants in a spec beyond which paired_plot shows their density


def paired_plot(per_participant: pd.DataFrame, conditions: tuple[str, ...], path: Path,
                belief_source: str = "") -> Path:
    """Per participant and spec: the mean reported trust under every condition, joined by a line;
    filled where the spec was satisfied. With two conditions a line is green when the first is the
    higher, red when the second is. Above MAX_PAIRED_LINES participants: `paired_density_plot`."""
    if len(per_participant) and per_participant["spec"].value_counts().max() > MAX_PAIRED_LINES:
        return paired_density_plot(per_participant, conditions, path, belief_source)
    plt = _pyplot()
    specs = list(dict.fromkeys(per_participant["spec"])) if len(per_participant) else [""]
    k = len(conditions)
    width = max(3.4, 1.3 * k + 1.0)
    fig, axes = plt.subplots(1, len(specs), figsize=(width * len(specs), 3.6), squeeze=False, sharey=True)
    rng = np.random.default_rng(0)  # jitter only, so overlapping participants stay visible
    for ax, spec in zip(axes[0], specs, strict=True):
        group = per_participant[per_participant["spec"] == spec]
        for row in group.itertuples(index=False):
            values = row._asdict()   # a condition without participants has no columns
            trust = [values.get(f"trust_{c}", np.nan) for c in conditions]
            satisfied = [values.get(f"satisfied_{c}", None) for c in conditions]
            jitter = rng.uniform(-0.04, 0.04)
            colour = "grey"
            if k == 2:
                colour = "#2ca02c" if trust[0] > trust[1] else "#d62728" if trust[0] < trust[1] else "grey"
            xs = np.arange(k) + jitter
            ax.plot(xs, trust, color=colour, alpha=0.6, lw=1)
            for x, y, sat in zip(xs, trust, satisfied, strict=True):
                if sat is None or pd.isna(sat):
                    continue
                ax.scatter([x], [y], s=22, zorder=3, edgecolor="black", linewidth=0.6,
                           color="black" if bool(sat) else "white")
        ax.set_xticks(list(range(k)), list(conditions))
        ax.set_xlim(-0.4, k - 0.6)
        ax.set_title(f"{spec} ({participants_note(group, conditions)})", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel("participant's mean reported trust")
    source = f" on {belief_source}" if belief_source else ""
    colours = f"; green = higher under {conditions[0]}" if k == 2 else ""
    _suptitle(fig, f"Per participant: {' / '.join(conditions)} (filled = spec satisfied{source}{colours})", 9)
    return _save(fig, path)


def participants_note(group: pd.DataFrame, conditions: tuple[str, ...]) -> str:
    """How many participants a panel of `paired_plot` shows, and how many of them drove every
    condition (the pairs the paired tests use) when some did not (an imported study's missing logs)."""
    driven = [f"satisfied_{c}" for c in conditions]
    complete = int(group.reindex(columns=driven).notna().all(axis=1).sum())
    return f"n={len(group)}" if complete == len(group) else (
        f"n={len(group)}, {complete} with every condition")


def paired_density_plot(per_participant: pd.DataFrame, conditions: tuple[str, ...], path: Path,
                        belief_source: str = "") -> Path:
    """`paired_plot` for many participants: per pair of conditions (A, B) (a row) and spec (a
    column), a 2-D histogram of each participant's mean reported trust under A (x) and B (y), the
    diagonal, and the counts on each side of it and of the satisfaction pairs (both, only A, only
    B, neither)."""

    plt = _pyplot()
    pairs = list(itertools.combinations(conditions, 2))
    specs = list(dict.fromkeys(per_participant["spec"]))
    trust = per_participant[[f"trust_{c}" for c in conditions]].to_numpy(dtype=float)
    finite = trust[np.isfinite(trust)]
    low, high = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
    edges = np.linspace(low - 0.05, high + 0.05, 25)  # coarse: means of few reports are on a lattice
    fig, axes = plt.subplots(len(pairs), len(specs), figsize=(4.6 * len(specs), 4.6 * len(pairs)),
                             squeeze=False)
    image = None
    for ax, ((a, b), spec) in zip(axes.flat, itertools.product(pairs, specs), strict=True):
        group = per_participant[per_participant["spec"] == spec]
        xa, yb = group[f"trust_{a}"].to_numpy(dtype=float), group[f"trust_{b}"].to_numpy(dtype=float)
        keep = np.isfinite(xa) & np.isfinite(yb)
        counts, _, _ = np.histogram2d(xa[keep], yb[keep], bins=[edges, edges])
        image = ax.pcolormesh(edges, edges, np.where(counts.T > 0, counts.T, np.nan), cmap="viridis",
                              shading="flat")
        ax.plot([edges[0], edges[-1]], [edges[0], edges[-1]], color="black", lw=0.8, ls="--")
        sat_a = group[f"satisfied_{a}"].astype(bool).to_numpy()
        sat_b = group[f"satisfied_{b}"].astype(bool).to_numpy()
        ax.set_title(f"{spec} (n={len(group)})", fontsize=9)
        ax.set_xlabel(f"mean reported trust, {a}\n\nhigher under {a}: {int((xa > yb).sum())}, "
                      f"under {b}: {int((xa < yb).sum())}\nequal: {int((xa == yb).sum())}\n"
                      f"satisfied both: {int((sat_a & sat_b).sum())}, neither: "
                      f"{int((~sat_a & ~sat_b).sum())}\nonly {a}: {int((sat_a & ~sat_b).sum())}, only {b}: "
                      f"{int((~sat_a & sat_b).sum())}", fontsize=8)
        ax.set_ylabel(f"mean reported trust, {b}")
        ax.set_aspect("equal")
    if image is not None:
        fig.colorbar(image, ax=list(axes.flat), label="participants", shrink=0.8)
    source = f", satisfaction on {belief_source}" if belief_source else ""
    fig.suptitle(f"Per participant: {' / '.join(conditions)} ({len(per_participant)} participant-spec "
                 f"rows, as a density{source})", fontsize=9)
    return _save(fig, path, tight_box=True)


def trust_plot(roads: pd.DataFrame, episodes: pd.DataFrame, path: Path, max_index: int = 30) -> Path:
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator
    merged = roads[["episode_id", "index", "trust_after", "reported_trust"]].merge(
        episodes[["episode_id", "spec", "condition"]], on="episode_id"
    )
    merged = merged[merged["index"] <= max_index]
    reported = pd.to_numeric(merged["reported_trust"], errors="coerce").astype(float)
    merged = merged.assign(reported=reported.where(reported >= 1))
    specs = list(dict.fromkeys(episodes["spec"]))
    fig, axes = plt.subplots(1, max(1, len(specs)), figsize=(4.2 * max(1, len(specs)), 3.4), squeeze=False)
    for ax, spec in zip(axes[0], specs, strict=False):
        notes: list[str] = []
        for j, condition in enumerate(dict.fromkeys(episodes["condition"])):
            group = merged[(merged["spec"] == spec) & (merged["condition"] == condition)]
            if group.empty:
                continue
            colour = COLOURS[j % len(COLOURS)]
            true, stats, band = trust_series(group)
            if len(band):
                ax.fill_between(band.index, band["low"], band["high"], color=colour, alpha=0.2, lw=0)
            notes.append(f"{condition}: {cell_note(true, stats, band)}")
            ax.plot(stats.index, stats["mean"], color=colour,
                    label=f"{condition} reported (mean, {BAND_LABEL})")
            if true.notna().any():   # people's hidden trust (imported, live) is unknown: no line
                ax.plot(true.index, true.values, color=colour, ls="--", lw=1, label=f"{condition} true")
        ax.set_title("\n".join([spec, *notes]), fontsize=8)
        ax.set_xlabel("road index (junctions driven)")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))   # a count of roads: no tick between two
        ax.set_ylim(1, 7)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("mean trust (Muir 1-7)")
    _legend_outside(axes[0][-1])
    fig.suptitle(f"Trust along the episodes (means where >= {MIN_LINE_EPISODES} episodes and >= 2% of them "
                 f"still run; bands where >= {MIN_BAND_EPISODES} report)", fontsize=9,
                 y=1.03 + 0.045 * episodes["condition"].nunique())  # above the panels' band notes
    return _save(fig, path, tight_box=True)


def cell_note(true: pd.Series, stats: pd.DataFrame, band: pd.DataFrame) -> str:
    """What a cell's reported mean rests on (`band_note`), or why it draws none: at no index enough
    of its episodes still run (a small study), or enough run and none reported trust."""
    if not len(true):
        return f"no mean (< {MIN_LINE_EPISODES} episodes at every index)"
    if not len(stats):
        return "no mean (no trust reports)"
    return band_note(band)


def band_note(band: pd.DataFrame) -> str:
    """How many episodes a trust band rests on (the range over its indices)."""
    if not len(band):
        return f"no band (< {MIN_BAND_EPISODES} reports per index)"
    low, high = int(band["count"].min()), int(band["count"].max())
    return f"band on {low} episodes" if low == high else f"band on {low}-{high} episodes"


def trust_series(group: pd.DataFrame) -> tuple[pd.Series, pd.DataFrame, pd.DataFrame]:
    """(mean true trust, reported mean/std/count, band low/high/count) by road index of one cell's
    roads (columns index, trust_after, reported): means only where enough episodes still run (a mean
    of two episodes is noise), the 95 % band only where MIN_BAND_EPISODES episodes report."""
    running = group.groupby("index").size()
    enough = running.index[running >= max(MIN_LINE_EPISODES, 0.02 * running.iloc[0])]
    true = group.groupby("index")["trust_after"].mean().loc[enough]
    stats = group.groupby("index")["reported"].agg(["mean", "std", "count"]).loc[enough]
    stats = stats[stats["count"] > 0]
    banded = stats[stats["count"] >= MIN_BAND_EPISODES]
    half = 1.96 * banded["std"].fillna(0) / np.sqrt(banded["count"])
    band = pd.DataFrame({"low": banded["mean"] - half, "high": banded["mean"] + half,
                         "count": banded["count"]})
    return true, stats, band


def _road_xy(town: Town, road: str, fraction: float = 0.5, offset: float = 18.0) -> tuple[float, float]:
    """A point `fraction` along a directed road's course, `offset` metres to its right (its
    driving side)."""
    return point_along(road_shape(town, road), fraction, offset)


def _undirected_shape(town: Town, u: str, v: str) -> np.ndarray:
    """The course of road u–v (its u-v direction, or v-u for a road one-way from v)."""
    road = Road(u, v).id if Road(u, v).id in town.incidents else Road(v, u).id
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
        s = float(share.get(Road(*sorted((u, v))).id, 0.0))
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
                road=group["directed_road"].map(lambda r: Road(*sorted(Road.parse(r))).id)
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
    return _save(fig, path, tight_box=True)


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
        ax.text(x, row.ci_high + 0.02, f"{row.takeovers}/{row.roads}", ha="center", va="bottom", fontsize=6,
                rotation=90)
    ax.set_xticks(range(len(incidents)), incidents)
    ax.set_ylim(0, 1.15)
    ax.set_ylabel("takeover rate")
    ax.set_title("Takeovers per incident met, exact 95% CI", fontsize=10)
    if conditions:
        _legend_outside(ax)
    return _save(fig, path, tight_box=True)


def write_plots(
    report_dir: Path, town: Town, analysis, roads: pd.DataFrame, specs_by_name: dict
) -> dict[str, Path]:
    """Every plot of the report into `<report_dir>/plots/`, by name."""
    folder = Path(report_dir) / PLOTS_DIR
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
        shown = [c for c in analysis.cells["condition"].drop_duplicates()
                 if f"trust_{c}" in analysis.per_participant]
        plots["participants"] = paired_plot(analysis.per_participant, tuple(shown),
                                            folder / "participants.png", analysis.belief_source)
    return plots
