"""Posterior-predictive check: how far simulated drivers are from the real participants.

Drivers of a model are simulated (trustroute/app/drivers.py, `simulate`; trustroute/app/runs.py,
`posterior_check`, puts the check together; this module only computes on the draws) on the real
episodes' own roads (the routes the participants
were driven, so route choice is held fixed and only the driver differs) with the synthetic
driver's step (participants/driver_step.py): θ_0 ~ π; on each road t >= 1 the takeover
h_t ~ P(h | θ_{t-1}, incident), the AV's performance e_t ~ P(fail | θ_{t-1}, incident),
θ_t ~ T[incident][h_t][e_t](θ_{t-1}, ·), and the report on arrival through the driver model's
noise model with the model's report accuracy (`draw_report`: θ_t, else one level up or down,
clipped), as the synthetic driver reports. Statistics compared with the real logs:

- takeover rate per incident type (per road driven); distance: |simulated - real| per incident;
- the distribution of the change of reported trust per road (r_t - r_{t-1}); total variation;
- the distribution of the final reported trust; total variation;
- roads with a changed report per episode (the real display changes by button presses; the
  simulated report is re-drawn each road); total variation.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.study.plots import save_figure
from trustroute.core.output_files import atomic_write_text
from trustroute.participants.driver_model import DriverModel

CHANGE_VALUES = np.arange(-6, 7)


@dataclass(frozen=True)
class Statistics:
    takeover_rate: dict[str, float]
    trust_change: np.ndarray  # probabilities over CHANGE_VALUES
    final_trust: np.ndarray  # probabilities over levels 1..7
    changes_per_episode: np.ndarray  # probabilities over 0..max_roads

    def to_dict(self) -> dict:
        return {
            "takeover_rate": self.takeover_rate,
            "trust_change": dict(
                zip(CHANGE_VALUES.tolist(), self.trust_change.round(6).tolist(), strict=True)
            ),
            "final_trust": self.final_trust.round(6).tolist(),
            "changes_per_episode": self.changes_per_episode.round(6).tolist(),
        }


def _histogram(values: np.ndarray, support: np.ndarray) -> np.ndarray:
    counts = np.array([(values == v).sum() for v in support], dtype=float)
    return counts / counts.sum() if counts.sum() else counts


def statistics(
    incident: np.ndarray,
    takeover: np.ndarray,
    report: np.ndarray,
    mask: np.ndarray,
    incident_types: tuple[str, ...],
    max_roads: int,
) -> Statistics:
    """incident/takeover [n, S] (roads 1..S), report [n, S+1] (column 0: the start road), mask [n, S]."""
    rates = {}
    for i, name in enumerate(incident_types):
        on = mask & (incident == i)
        if on.any():
            rates[name] = float(takeover[on].mean())
    change = (report[:, 1:] - report[:, :-1])[mask]
    lengths = mask.sum(axis=1)
    final = report[np.arange(report.shape[0]), lengths]
    changed = ((report[:, 1:] != report[:, :-1]) & mask).sum(axis=1)
    return Statistics(
        takeover_rate=rates,
        trust_change=_histogram(change, CHANGE_VALUES),
        final_trust=_histogram(final, np.arange(1, 8)),
        changes_per_episode=_histogram(changed, np.arange(max_roads + 1)),
    )


def real_arrays(roads: pd.DataFrame, model: DriverModel) -> tuple[np.ndarray, ...]:
    """(incident index, takeover, reported trust, mask) padded per episode from a roads table.

    Episodes in sorted id order, each one's roads in `index` order; filled column by column (a
    scatter by episode and position), not episode by episode: a posterior check reads thousands of
    simulated episodes."""
    roads = roads.sort_values(["episode_id", "index"], kind="stable")
    roads = roads[roads["episode_id"].notna()]   # as a groupby by episode id would drop them
    if roads.empty:
        raise ValueError("no roads to read")
    episode, _ = pd.factorize(roads["episode_id"], sort=True)
    lengths = np.bincount(episode)
    first = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    position = np.arange(len(roads)) - first[episode]   # the road's place in its episode, from 0
    steps = int(lengths.max()) - 1
    n = lengths.size
    incident = np.zeros((n, steps), dtype=np.int64)
    takeover = np.zeros((n, steps), dtype=bool)
    mask = np.zeros((n, steps), dtype=bool)
    after = position >= 1   # the roads after the first: one step each
    codes, kinds = pd.factorize(roads["incident"].iloc[np.flatnonzero(after)], use_na_sentinel=False)
    rows, cols = episode[after], position[after] - 1
    incident[rows, cols] = np.array([model.incident_index(x) for x in kinds], dtype=np.int64)[codes]
    takeover[rows, cols] = roads["takeover"].iloc[np.flatnonzero(after)].fillna(False).to_numpy(dtype=bool)
    mask[rows, cols] = True
    reports = roads["reported_trust"].to_numpy(dtype=np.int64, na_value=4)
    last = reports[first + lengths - 1]
    report = np.repeat(last[:, None], steps + 1, axis=1)   # each episode's last report repeated to the end
    report[episode, position] = reports
    return incident, takeover, report, mask


def total_variation(p: np.ndarray, q: np.ndarray) -> float:
    size = max(p.size, q.size)
    return 0.5 * float(np.abs(np.pad(p, (0, size - p.size)) - np.pad(q, (0, size - q.size))).sum())


def distances(sim: Statistics, real: Statistics) -> dict:
    return {
        "takeover_rate_abs_difference": {
            name: abs(sim.takeover_rate.get(name, 0.0) - rate) for name, rate in real.takeover_rate.items()
        },
        "trust_change_tv": total_variation(sim.trust_change, real.trust_change),
        "final_trust_tv": total_variation(sim.final_trust, real.final_trust),
        "changes_per_episode_tv": total_variation(sim.changes_per_episode, real.changes_per_episode),
    }


def check_of(roads: pd.DataFrame, template: DriverModel, replicates: int) -> tuple[dict, Statistics]:
    """The check's frame from the real logs (`template` reads the incidents): its sizes, the real
    statistics, and an empty "models" entry that `add_model` fills."""
    incident, takeover, report, mask = real_arrays(roads, template)
    real = statistics(incident, takeover, report, mask, template.incident_types, max_roads(mask))
    check = {"replicates": replicates, "episodes": int(mask.shape[0]), "roads": int(mask.sum()),
             "real": real.to_dict(), "models": {}, "_stats": {"real": real}}
    return check, real


def max_roads(mask: np.ndarray) -> int:
    return int(mask.sum(axis=1).max())


def add_model(check: dict, name: str, model: DriverModel, accuracy: float, incident: np.ndarray,
              mask: np.ndarray, takeover: np.ndarray, report: np.ndarray) -> None:
    """One model's simulated drivers (takeovers and reports on the real roads, `replicates` per
    episode, drawn outside the analysis: trustroute/app/runs.py) into `check`: its statistics and
    their distances to the real ones."""
    replicates = check["replicates"]
    sim = statistics(np.repeat(incident, replicates, axis=0), takeover, report,
                     np.repeat(mask, replicates, axis=0), model.incident_types, max_roads(mask))
    check["_stats"][name] = sim
    check["models"][name] = {"report_accuracy": accuracy, "statistics": sim.to_dict(),
                             "distance": distances(sim, check["_stats"]["real"])}


# Each panel of the check's figure: (title, x label, y label). The rates and shares are fractions
# (no unit); trust is on the 1-7 scale, its changes in levels.
CHECK_PANELS = (
    ("takeover rate per incident", "incident on the road", "takeovers per road driven"),
    ("reported trust change per road", "change of the reported trust on a road (levels)", "share of roads"),
    ("final reported trust", "reported trust at the episode's end (level, 1-7)", "share of episodes"),
    ("roads with a changed report per episode", "roads whose report changed", "share of episodes"),
)


def plot_check(check: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stats: dict[str, Statistics] = check["_stats"]
    fig, axes = plt.subplots(1, len(CHECK_PANELS), figsize=(18, 4))
    names = list(stats)
    width = 0.8 / len(names)
    incidents = list(stats["real"].takeover_rate)
    for j, name in enumerate(names):
        s = stats[name]
        shift = (j - (len(names) - 1) / 2) * width   # each value's bars centred on its tick
        axes[0].bar(np.arange(len(incidents)) + shift, [s.takeover_rate.get(i, 0) for i in incidents], width,
                    label=name)
        axes[1].bar(CHANGE_VALUES + shift, s.trust_change, width, label=name)
        axes[2].bar(np.arange(1, 8) + shift, s.final_trust, width, label=name)
        axes[3].bar(np.arange(s.changes_per_episode.size) + shift, s.changes_per_episode, width, label=name)
    axes[0].set_xticks(np.arange(len(incidents)), incidents)
    for ax, (title, x_label, y_label) in zip(axes, CHECK_PANELS, strict=True):
        ax.set_title(title)
        ax.set_xlabel(x_label)
        ax.set_ylabel(y_label)
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return Path(path)


def write_check(check: dict, path: Path) -> Path:
    payload = {k: v for k, v in check.items() if not k.startswith("_")}
    return atomic_write_text(path, json.dumps(payload, indent=1), "posterior check",
                             "pass a writable path with --out")
