"""A study's design as far as its data show it, where its config does not say: how many
participants it had (an imported study's config has no count; a live study's is the number
planned, not of the people who took part), and whether every participant drove
the cells in one fixed order (an imported study's sessions; then position is confounded with the
cell, and no order effect is estimable).
"""

from __future__ import annotations

import pandas as pd

from trustroute.core.wording import counted
from trustroute.harness.study.config import ENGINES, LIVE_ENGINE


def study_participants(manifest: dict, episodes: pd.DataFrame) -> int:
    """The study's participants: those in its episodes for a live study (a withdrawn participant's
    data are deleted, one who declined has none, the config counts the participants planned) and an
    imported one (its config has no count); the config's count for a simulated study, every planned
    participant of which is run."""
    configured = manifest.get("config", {}).get("participants")
    if configured is not None and manifest.get("engine") != LIVE_ENGINE:
        return int(configured)
    return int(episodes["participant"].nunique()) if "participant" in episodes else 0


def participants_text(manifest: dict, episodes: pd.DataFrame) -> str:
    """The participants as the report's design line shows them: a live study's with the number
    planned beside them."""
    text = counted(study_participants(manifest, episodes), "participant")
    planned = manifest.get("config", {}).get("participants")
    if manifest.get("engine") == LIVE_ENGINE and planned is not None:
        text += f" with data (of {int(planned)} planned)"
    return text


def fixed_order(episodes: pd.DataFrame) -> list[tuple[str, str]] | None:
    """The (spec, condition) cells by position when at least two participants drove them all in one
    order (each position holds one cell, each cell sits at one position; a participant may miss a
    cell); None otherwise."""
    if not len(episodes) or episodes["participant"].nunique() < 2:
        return None
    cells_at = episodes.groupby("position")[["spec", "condition"]].nunique()
    positions_of = episodes.groupby(["spec", "condition"])["position"].nunique()
    if (cells_at > 1).to_numpy().any() or (positions_of > 1).any():
        return None
    first = episodes.drop_duplicates("position").sort_values("position")
    return list(zip(first["spec"], first["condition"], strict=True))


def order_text(order) -> str:
    """A fixed order as shown: "phi1 aware, phi1 free, ..."."""
    return ", ".join(f"{spec} {condition}" for spec, condition in order)


def design_text(manifest: dict, episodes: pd.DataFrame) -> str:
    """How the cells were ordered and seeded: what the data and the config show, nothing assumed."""
    seed = manifest.get("config", {}).get("seed")
    seeded = f"seed {seed}" if seed is not None else "no seed"
    order = fixed_order(episodes)
    if order is not None:
        return f"{seeded}, every participant in one fixed order ({order_text(order)}), not counterbalanced"
    if manifest.get("engine") in ENGINES:   # planned from a study config: each order is a Williams row
        return f"{seeded}, counterbalanced by a Williams Latin square"
    return f"{seeded}, in the orders recorded"
