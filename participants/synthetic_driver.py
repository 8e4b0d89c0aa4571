"""The synthetic driver: one simulated participant with a hidden trust level.

Owns `SyntheticDriver`, the human side of an episode used by both the SUMO engine and the
model engine. Its trust is hidden from the AV; it decides takeovers from its current trust
(the driver model's takeover probability), moves its trust by the model's trust dynamics
T[inc][h][e](θ, θ'), and reports its trust with a configurable accuracy. In the model engine
it also draws the AV's performance from the model's failure probability.
The report noise model is the driver model's (participants/driver_model.py); see docs/model.md,
"The model". Every draw goes through the Generator passed in.
"""

from __future__ import annotations

import bisect

import numpy as np

from trustroute.participants.driver_model import (
    DEFAULT_REPORT_ACCURACY,
    PERFORMANCES,
    DriverModel,
    draw_report,
)


def _draw_index(probabilities: np.ndarray, rng: np.random.Generator) -> int:
    """One draw from a discrete distribution (inverse CDF; robust to rows summing to 1 ± 1e-9)."""
    return _draw_from_cdf(np.cumsum(probabilities).tolist(), rng)


def _draw_from_cdf(cdf: list[float], rng: np.random.Generator) -> int:
    """`_draw_index` on a cumulative row as floats: bisect_right is searchsorted(side="right") on
    the same doubles, so the index is the same."""
    return min(bisect.bisect_right(cdf, rng.random() * cdf[-1]), len(cdf) - 1)


_TRANSITION_CDFS: dict[int, tuple[DriverModel, list]] = {}


def _transition_cdfs(model: DriverModel) -> list:
    """The cumulative rows of the model's trust transition T[inc][h][e](θ, ·) as nested lists,
    built once per model (np.cumsum along the last axis adds in the order it does on one row)."""
    entry = _TRANSITION_CDFS.get(id(model))
    if entry is None or entry[0] is not model:
        if len(_TRANSITION_CDFS) > 64:
            _TRANSITION_CDFS.clear()
        entry = (model, np.cumsum(np.asarray(model.trust_transition, dtype=float), axis=-1).tolist())
        _TRANSITION_CDFS[id(model)] = entry
    return entry[1]



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
        cdf = _transition_cdfs(self.model)[self._incident(incident)][int(bool(took_over))][
            PERFORMANCES.index(performance)][self._theta]
        self._theta = _draw_from_cdf(cdf, self.rng)
        return self.trust

    def report_trust(self) -> int:
        """A report of the current trust through the driver model's noise model (draw_report):
        the true level with probability report_accuracy, else one level off, clipped."""
        reported = draw_report(self._theta, self.report_accuracy, self.model.n_trust, self.rng)
        return self.model.trust_levels[reported]
