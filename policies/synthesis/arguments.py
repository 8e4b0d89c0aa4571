"""The argument checks every synthesis entry point shares (policies/synthesis/belief_synthesis.py,
policies/synthesize_spec.py): one definition of what a valid tau, horizon and belief rule are."""

from __future__ import annotations

BELIEF_RULES = ("bayes", "paper")


def check_synthesis_arguments(tau: float, horizon: int | None, belief_rule: str) -> None:
    """ValueError naming the first bad argument."""
    if tau <= 0:
        raise ValueError("tau must be positive")
    if horizon is not None and horizon < 0:
        raise ValueError("horizon must be >= 0")
    if belief_rule not in BELIEF_RULES:
        raise ValueError(f"unknown belief rule {belief_rule!r}; use 'bayes' or 'paper'")
