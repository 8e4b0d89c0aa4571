"""The manual-driving measures per incident type and condition (the incidents table's takeover
rows, docs/dataset.md): takeovers, the mean reaction from the incident in view to the takeover,
and, over the takeovers driven by wheel, the mean SD of lateral position, the least time to
collision, the mean largest deceleration, the mean time in the oncoming lane, and the road
departures and collisions counted. Empty without an incidents table or takeovers.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from trustroute.analysis.formatting import number_text
from trustroute.core.dataset import MANUAL_MEASURES, read_incidents

MANUAL_COLUMNS = (
    "incident", "condition", "takeovers", "reaction_s", "by_wheel", "lateral_sd_m", "min_ttc_s",
    "max_deceleration", "oncoming_s", "road_departures", "collisions",
)


def study_incidents(study_dir: Path) -> pd.DataFrame:
    """The takeover rows of the study's incidents table with the measures (none: empty; a study
    without the table has none, `read_incidents`)."""
    incidents = read_incidents(study_dir, ["episode_id", "incident", "takeover", *MANUAL_MEASURES])
    return incidents[incidents["takeover"].astype(bool)]


def _mean(values: pd.Series) -> float:
    values = pd.to_numeric(values, errors="coerce").dropna()
    return float(values.mean()) if len(values) else float("nan")


def manual_table(incidents: pd.DataFrame, episodes: pd.DataFrame, condition_order) -> pd.DataFrame:
    if not len(incidents):
        return pd.DataFrame(columns=list(MANUAL_COLUMNS))
    merged = incidents.merge(episodes[["episode_id", "condition"]], on="episode_id")
    rows = []
    for (incident, condition), group in merged.groupby(["incident", "condition"], sort=True):
        wheel = group[group["lateral_sd"].notna()]
        ttc = pd.to_numeric(wheel["manual_min_ttc"], errors="coerce").dropna()
        rows.append({
            "incident": incident, "condition": condition, "takeovers": len(group),
            "reaction_s": _mean(group["takeover_reaction"]), "by_wheel": len(wheel),
            "lateral_sd_m": _mean(wheel["lateral_sd"]),
            "min_ttc_s": float(ttc.min()) if len(ttc) else float("nan"),
            "max_deceleration": _mean(wheel["manual_max_deceleration"]),
            "oncoming_s": _mean(wheel["oncoming_seconds"]),
            "road_departures": int(pd.to_numeric(wheel["road_departures"]).fillna(0).sum()),
            "collisions": int(pd.to_numeric(wheel["collisions"]).fillna(0).sum()),
        })
    table = pd.DataFrame(rows, columns=list(MANUAL_COLUMNS))
    order = {c: i for i, c in enumerate(condition_order)}
    table["_order"] = table["condition"].map(order).fillna(len(order))
    return table.sort_values(["incident", "_order"]).drop(columns="_order").reset_index(drop=True)


def manual_display(m: pd.DataFrame) -> pd.DataFrame:
    """The table as shown: each measure rounded as every other table rounds it (formatting.py
    `number_text`: "inf" where infinite, "-" where not measured)."""
    def number(values: pd.Series, digits: int) -> list[str]:
        return [number_text(v, digits) for v in values]

    return pd.DataFrame({
        "incident": m["incident"], "condition": m["condition"], "takeovers": m["takeovers"],
        "reaction (s)": number(m["reaction_s"], 2), "by wheel": m["by_wheel"],
        "SD lateral (m)": number(m["lateral_sd_m"], 2), "min TTC (s)": number(m["min_ttc_s"], 2),
        "max decel (m/s²)": number(m["max_deceleration"], 2), "oncoming (s)": number(m["oncoming_s"], 1),
        "road departures": m["road_departures"], "collisions": m["collisions"],
    })
