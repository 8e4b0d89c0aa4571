"""The paper's published figures (Yu et al., ICRA 2024), the one place they are written.

Quoted to be compared with, never asserted: the simulated study's report sets them beside its own
(analysis/study/paper_comparison.py), the real-study analysis looks for the readings of the released
logs that reproduce them (analysis/carla_study/analysis.py), and the benchmarks print them beside
the synthesized bounds. docs/study.md, "Headline figures of the paper", lists them.
"""

from __future__ import annotations

from collections.abc import Mapping

PARTICIPANTS = 21
# Participants satisfying each spec under the trust-aware condition: (satisfied, participants).
SATISFIED_AWARE: dict[str, tuple[int, int]] = {"phi1": (18, PARTICIPANTS), "phi2": (17, PARTICIPANTS)}
SATISFACTION_RATE: dict[str, float] = {"aware": 0.85, "free": 0.775}
MEAN_TRUST: dict[str, float] = {"aware": 4.6018, "free": 4.3933}  # average reported trust
PR_MAX: dict[str, float] = {"phi1": 0.8357, "phi2": 0.7288}  # synthesized, unbounded, tau = 0.01


def count_text(spec: str) -> str:
    """The paper's count of participants satisfying `spec` (aware) as printed: "18/21"."""
    satisfied, participants = SATISFIED_AWARE[spec]
    return f"{satisfied}/{participants}"


def aware_vs_free_text(figure: Mapping[str, float]) -> str:
    """A per-condition figure as printed: "0.85 vs 0.775"."""
    return f"{figure['aware']} vs {figure['free']}"
