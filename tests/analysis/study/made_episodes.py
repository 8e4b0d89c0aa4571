"""Hand-made episodes tables for the analysis tables: every column the cells and the paired tables
read, drawn from a seeded Generator."""

from __future__ import annotations

import numpy as np
import pandas as pd

SOURCES = ("filter", "reported", "reference", "true")


def made_episodes(participants: int = 14, specs=("phi1", "phi2"), conditions=("aware", "robust", "free"),
                  types=("builder", "wary"), seed: int = 3) -> pd.DataFrame:
    """One episode per (participant, spec, condition); satisfaction is the same on every belief
    source (`satisfied_<source>`), trust reports are whole numbers 1-7, and participant p has the
    type types[p % len(types)]."""
    rng = np.random.default_rng(seed)
    rows = []
    for person in range(participants):
        for spec in specs:
            for k, condition in enumerate(conditions):
                satisfied = bool(rng.random() < 0.85 - 0.2 * k)
                rows.append({
                    "episode_id": f"p{person:05d}-{spec}-{condition}", "participant": person, "spec": spec,
                    "condition": condition, "driver_type": types[person % len(types)],
                    "satisfied": satisfied, **{f"satisfied_{s}": satisfied for s in SOURCES},
                    "mean_reported_trust": float(rng.integers(1, 8)), "mean_trust": float(rng.uniform(1, 7)),
                    "final_trust": int(rng.integers(1, 8)), "junctions": int(rng.integers(3, 9)),
                    "takeovers": int(rng.integers(0, 3)), "fallback_fired": False,
                })
    return pd.DataFrame(rows)
