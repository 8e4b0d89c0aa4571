"""The synthetic driver: one simulated participant with a hidden trust level.

Owns `SyntheticDriver`, the human side of an episode used by both the SUMO engine and the
model engine. Its trust is hidden from the AV; it decides takeovers from its current trust
(the driver model's takeover probability), moves its trust by the model's trust dynamics
T[inc][h][e](θ, θ'), and reports its trust with a configurable accuracy. In the model engine
it also draws the AV's performance from the model's failure probability.
See ../shared/DESIGN.md, "The model". Every draw goes through the Generator passed in.
"""

from __future__ import annotations

import numpy as np

from trustroute.participants.driver_model import PERFORMANCES, DriverModel


def _draw_index(probabilities: np.ndarray, rng: np.random.Generator) -> int:
    """One draw from a discrete distribution (inverse CDF; robust to rows summing to 1 ± 1e-9)."""
    cdf = np.cumsum(probabilities)
    return min(int(np.searchsorted(cdf, rng.random() * cdf[-1], side="right")), cdf.size - 1)


# The synthetic driver's report accuracy unless a study says otherwise (a project choice,
# participants/data/PROVENANCE.md).
DEFAULT_REPORT_ACCURACY = 0.8

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
        if initial_trust is None:
            self._theta = _draw_index(model.initial_belief, rng)
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
        p = self.model.takeover_probability[self._incident(incident), self._theta]
        return bool(self.rng.random() < p)

    def performance(self, incident: str) -> str:
        """The AV's performance e ~ P(fail | θ, inc) (model engine; SUMO observes it instead).

        One uniform draw is taken even when the model cannot fail, so a model with and one
        without failures consume the random stream alike.
        """
        p = self.model.failure_probability[self._incident(incident), self._theta]
        return PERFORMANCES[int(self.rng.random() < p)]

    def move_trust(self, incident: str, took_over: bool, performance: str = "succ") -> int:
        """θ' ~ T[inc][h][e](θ, ·); returns the new trust level."""
        if performance not in PERFORMANCES:
            raise ValueError(f"performance {performance!r} is not one of {PERFORMANCES}")
        row = self.model.trust_transition[self._incident(incident), int(bool(took_over)),
                                          PERFORMANCES.index(performance), self._theta]
        self._theta = _draw_index(row, self.rng)
        return self.trust

    def report_trust(self) -> int:
        """True trust with probability report_accuracy, else one level up or down (equal chance),
        clipped to the model's levels (so at 1 and 7 a wrong report can still equal the truth)."""
        if self.rng.random() < self.report_accuracy:
            return self.trust
        step = -1 if self.rng.random() < 0.5 else 1
        reported = min(max(self._theta + step, 0), self.model.n_trust - 1)
        return self.model.trust_levels[reported]
