"""The synthetic driver: one simulated participant with a hidden trust level.

Owns `SyntheticDriver`, the human side of an episode used by both the SUMO engine and the
model engine. Its trust is hidden from the AV; it decides takeovers from its current trust
(the driver model's takeover probability), moves its trust by the model's trust dynamics
T[inc][h][e](θ, θ'), and reports its trust with a configurable accuracy. In the model engine
it also draws the AV's performance from the model's failure probability.
Every draw is participants/driver_step.py's, on a single driver (the batch of one of the model
engine's batch path, POUCT and the posterior check); the report noise model is the driver model's
(participants/driver_model.py); see docs/model.md, "The model". Every draw goes through the
Generator passed in.
"""

from __future__ import annotations

import numpy as np

from trustroute.participants.driver_model import (
    DEFAULT_REPORT_ACCURACY,
    PERFORMANCES,
    DriverModel,
)
from trustroute.participants.driver_step import (
    draw_initial_trust,
    draw_performances,
    draw_reports,
    draw_takeovers,
    draw_trust,
)

KIND = 0   # the driver's model is kind 0 of its own tables


class SyntheticDriver:
    """A participant-episode: hidden true trust `trust` (a level of model.trust_levels)."""

    def __init__(self, model: DriverModel, rng: np.random.Generator,
                 report_accuracy: float = DEFAULT_REPORT_ACCURACY,
                 initial_trust: int | None = None) -> None:
        if not 0.0 <= report_accuracy <= 1.0:
            raise ValueError(f"report_accuracy {report_accuracy!r} is not a probability in [0, 1]")
        self.model = model
        self.rng = rng
        self.report_accuracy = float(report_accuracy)
        self._tables = model.tables
        if initial_trust is None:
            self._theta = int(draw_initial_trust(self._tables, KIND, rng))
        elif initial_trust in model.trust_levels:
            self._theta = model.trust_levels.index(initial_trust)
        else:
            raise ValueError(f"initial trust {initial_trust!r} is not one of the model's levels "
                             f"{model.trust_levels}")

    @property
    def trust(self) -> int:
        """The current true trust level (hidden from the AV)."""
        return self.model.trust_levels[self._theta]

    @property
    def trust_index(self) -> int:
        return self._theta

    def _incident(self, incident: str) -> int:
        if incident not in self.model.incident_types:
            raise ValueError(f"incident {incident!r} is not covered by the driver model "
                             f"{self.model.source_path} ({', '.join(self.model.incident_types)})")
        return self.model.incident_index(incident)

    def decides_takeover(self, incident: str) -> bool:
        """h ~ P(takeover | θ, inc) at the current trust θ."""
        return bool(draw_takeovers(self._tables, KIND, self._incident(incident), self._theta, self.rng))

    def performance(self, incident: str) -> str:
        """The AV's performance e ~ P(fail | θ, inc) (model engine; SUMO observes it instead)."""
        e = draw_performances(self._tables, KIND, self._incident(incident), self._theta, self.rng)
        return PERFORMANCES[e]

    def move_trust(self, incident: str, took_over: bool, performance: str = "succ") -> int:
        """θ' ~ T[inc][h][e](θ, ·); returns the new trust level."""
        if performance not in PERFORMANCES:
            raise ValueError(f"performance {performance!r} is not one of {PERFORMANCES}")
        self._theta = int(draw_trust(self._tables, KIND, self._incident(incident), int(bool(took_over)),
                                     PERFORMANCES.index(performance), self._theta, self.rng))
        return self.trust

    def report_trust(self) -> int:
        """A report of the current trust through the driver model's noise model (draw_report):
        the true level with probability report_accuracy, else one level off, clipped."""
        return self.model.trust_levels[draw_reports(self._theta, self.report_accuracy,
                                                    self.model.n_trust, self.rng)]
