"""Shared test helpers for the harness tests: spec paths, a fixed-route policy, forced drivers, and
a finished study from a config text."""

from __future__ import annotations

from pathlib import Path

from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.policies.routing.fixed_route import FixedRoute as FixedRoute  # the tests take it from here

SPECS = PACKAGED_SPECS
# Start E-A, then a pedestrian road, a plain road, an obstacle road and a truck road.
INCIDENT_ROUTE = ("E-A", "A-B", "B-C", "C-J", "J-K")


def run_study(config_path: Path, text: str, out: Path):
    """Write the study config `text` to `config_path`, run and consolidate that study into `out` on
    one local worker without output, and return its StudyConfig."""
    from trustroute.harness.study.config import load_study_config
    from trustroute.harness.study.runner import run_and_consolidate

    config_path.write_text(text)
    config = load_study_config(config_path)
    run_and_consolidate(config, out, 1, None, progress=False, echo=lambda *_: None)
    return config


class ForcedTakeover:
    """A synthetic driver that takes over at every incident of the given kinds (test stand-in)."""

    def __init__(self, driver, kinds=("pedestrian", "obstacle", "truck")) -> None:
        self.inner = driver
        self.kinds = tuple(kinds)

    @property
    def trust(self) -> int:
        return self.inner.trust

    def decides_takeover(self, incident: str) -> bool:
        self.inner.decides_takeover(incident)
        return incident in self.kinds

    def move_trust(self, incident: str, took_over: bool, performance: str = "succ") -> int:
        return self.inner.move_trust(incident, took_over, performance)

    def report_trust(self) -> int:
        return self.inner.report_trust()
