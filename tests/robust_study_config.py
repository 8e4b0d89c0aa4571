"""The config of a small model-engine study of the three packaged driver types under aware, robust
and free, at horizon 3 (synthesis stays fast; aware and robust are then their fallback)."""

from __future__ import annotations

from pathlib import Path

from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH


def robust_study_text(root: Path, participants: int, drivers: bool = True) -> str:
    """The study's TOML: its policies cached under `root`; with `drivers`, the types as its
    drivers too (a plan reads the config without them)."""
    text = f"""[study]
participants = {participants}
seed = 5
engine = "model"
specs = ["phi1"]
conditions = ["aware", "robust", "free"]
horizon = 3
policy_cache = "{root / 'cache'}"
robust_population = "{EXAMPLE_POPULATION_PATH}"
"""
    return text + (f'\n[drivers]\npopulation = "{EXAMPLE_POPULATION_PATH}"\n' if drivers else "")
