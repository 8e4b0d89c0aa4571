"""The paper's figures (analysis/paper_figures.py) beside a study's, for a study comparable to the
paper's (its town, its φ1 and φ2, 21 participants, the aware and free conditions); otherwise a note
saying why not.
"""

from __future__ import annotations

import pandas as pd

from trustroute.analysis import paper_figures
from trustroute.analysis.formatting import MISSING, bounds_text
from trustroute.analysis.statistics import rate_interval
from trustroute.analysis.study.design import study_participants
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.core.wording import counted
from trustroute.harness.study.inputs import found_spec, recorded_stem
from trustroute.networks.town import load_town
from trustroute.policies.logic.spec import load_spec


def is_paper_comparable(manifest: dict, episodes: pd.DataFrame) -> tuple[bool, str]:
    """The paper's table applies to the paper's town, its φ1 and φ2 and 21 participants only."""
    config = manifest.get("config", {})
    reasons = []
    participants = study_participants(manifest, episodes)
    if participants != paper_figures.PARTICIPANTS:
        reasons.append(f"{counted(participants, 'participant')}, the paper had {paper_figures.PARTICIPANTS}")
    default_town = load_town(None)
    town = load_town(config.get("town")) if config.get("town") else default_town
    if town.content_hash != default_town.content_hash:
        reasons.append("another town")
    for name in ("phi1", "phi2"):
        ours = [i for i, p in enumerate(config.get("specs", [])) if recorded_stem(p) == name]
        found = found_spec(config, ours[0]) if ours else None   # None: not provably any spec
        if (
            found is None
            or load_spec(found, town).content_hash
            != load_spec(PACKAGED_SPECS / f"{name}.toml", town).content_hash
        ):
            reasons.append(f"not the paper's {name}")
    if not {"aware", "free"} <= set(episodes["condition"]):
        reasons.append("not the aware and free conditions")
    if reasons:
        return False, (
            "The paper's figures are not shown: this study is not comparable to it ("
            + "; ".join(reasons)
            + ")."
        )
    return True, ""


def paper_comparison(episodes: pd.DataFrame, cells: pd.DataFrame, belief_source: str) -> list[dict]:
    """The paper's headline figures beside this study's (docs/study.md, "Headline figures of the paper"):
    `episodes` with a satisfied_<belief_source> column, `cells` the study's cell table."""
    source = belief_source
    rows = []
    for spec in paper_figures.SATISFIED_AWARE:
        group = episodes[(episodes["spec"] == spec) & (episodes["condition"] == "aware")]
        satisfied = int(group[f"satisfied_{source}"].sum())
        low, high = rate_interval(satisfied, len(group))
        rows.append(
            {
                "figure": f"participants satisfying {spec} (aware)",
                "paper": paper_figures.count_text(spec),
                "ours": f"{satisfied}/{len(group)} (exact 95% CI [{low:.3f}, {high:.3f}])",
            }
        )

    def by_condition(column: str, digits: int) -> str:
        values = []
        for condition in ("aware", "free"):
            group = episodes[episodes["condition"] == condition]
            values.append(f"{group[column].mean():.{digits}f}" if len(group) else "not run")
        return " vs ".join(values)

    rows.append(
        {
            "figure": "satisfaction aware vs free",
            "paper": paper_figures.aware_vs_free_text(paper_figures.SATISFACTION_RATE),
            "ours": by_condition(f"satisfied_{source}", 3),
        }
    )
    rows.append(
        {
            "figure": "average trust aware vs free (reported)",
            "paper": paper_figures.aware_vs_free_text(paper_figures.MEAN_TRUST),
            "ours": by_condition("mean_reported_trust", 4),
        }
    )
    by_cell = cells.set_index(["spec", "condition"]) if len(cells) else None
    for spec, value in paper_figures.PR_MAX.items():
        ours = "not available"
        within = ""
        if by_cell is not None and (spec, "aware") in by_cell.index:
            cell = by_cell.loc[(spec, "aware")]
            shown = bounds_text(cell["synthesized_lower"], cell["synthesized_upper"], 4)
            if shown != MISSING:
                ours = shown
            if cell["synthesized_horizon"] is not None and not pd.isna(cell["synthesized_horizon"]):
                within = f", ours within H={int(cell['synthesized_horizon'])} junctions"
        rows.append({"figure": f"Pr_max({spec}), synthesized{within}", "paper": f"{value}", "ours": ours})
    return rows
