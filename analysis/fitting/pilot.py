"""A pilot study as the participants of a plan (`trustroute plan --pilot DIR`, docs/planning.md).

The driver model is fitted on the pilot's logs by `fit_study`, the very fit `trustroute fit`
runs (method "auto": counts when the pilot's reports are exact and on every road, else EM), and
refitted on bootstrap resamples of the pilot's participants by `bootstrap_refits`, the refits
`trustroute fit --bootstrap` summarises. The refits carry the fit's uncertainty: a plan draws one
refit per simulated study, so its power is averaged over what the pilot leaves open. With no
resample the point fit stands alone (no uncertainty drawn).

Reports in the simulated studies are drawn with the point fit's report accuracy (one number for
every refit: the model engine draws a batch's reports with one accuracy).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trustroute.analysis.fitting.driver_model import bootstrap_refits, fit_study
from trustroute.analysis.study_directory import load_study, study_inputs
from trustroute.core import defaults
from trustroute.core.dataset import EPISODES_FILE, MANIFEST_FILE, ROADS_FILE
from trustroute.core.errors import InputError
from trustroute.core.wording import counted
from trustroute.participants.driver_model import DriverModel

# Fewer participants leave the bootstrap too few distinct resamples to speak of uncertainty
# (3 participants: 10 distinct resamples, 4: 35, 8: 6,435).
MIN_PILOT_PARTICIPANTS = 4


@dataclass(frozen=True, eq=False)
class PilotFit:
    """The fit of a pilot: the point fit, its `refits` on resamples of the participants (empty:
    none asked) and what they rest on."""

    source: str
    participants: int
    episodes: int
    roads: int
    reports: int
    method: str
    fitted: DriverModel
    report_accuracy: float
    refits: tuple[DriverModel, ...]
    converged: int   # of the point fit and the refits, how many converged (counts always do)

    @property
    def models(self) -> tuple[DriverModel, ...]:
        """The models a plan draws from: the refits, or the point fit when there are none."""
        return self.refits or (self.fitted,)

    def label(self) -> str:
        uncertainty = (f"{len(self.refits)} bootstrap refits, one drawn per simulated study" if self.refits
                       else "no bootstrap refit: the point fit alone, its uncertainty not drawn")
        return (f"pilot fit of {self.participants} participants ({self.source}, {self.method}) with "
                f"{uncertainty}")

    def summary(self) -> dict:
        return {"study": self.source, "participants": self.participants, "episodes": self.episodes,
                "roads": self.roads, "reports": self.reports, "method": self.method,
                "bootstrap_refits": len(self.refits), "converged": self.converged,
                "fits": 1 + len(self.refits), "report_accuracy": self.report_accuracy}


def check_pilot(study_dir: Path, expected: DriverModel | None = None):
    """(manifest, episodes, roads, template) of a pilot study a plan can fit, or InputError: not a
    finished study, too few participants, no trust report, or (given `expected`, the AV's driver
    model) other trust levels or incidents than it has."""
    manifest, episodes, roads = load_study(study_dir)
    participants = int(episodes["participant"].nunique())
    if participants < MIN_PILOT_PARTICIPANTS:
        raise InputError(str(study_dir / EPISODES_FILE), "participant",
                         f"the pilot has {counted(participants, 'participant')}; fitting it with its "
                         f"uncertainty needs at least {MIN_PILOT_PARTICIPANTS}",
                         "run a pilot of at least 4 participants (8 or more: the fit is wide), or plan "
                         "with --driver")
    if int(roads["reported_trust"].notna().sum()) == 0:
        raise InputError(str(study_dir / ROADS_FILE), "reported_trust",
                         "no road carries a trust report, so the trust dynamics cannot be fitted",
                         "plan from a pilot whose drivers report trust (report_every in its config), "
                         "or plan with --driver")
    _, template, _ = study_inputs(manifest, study_dir)
    if expected is not None and (tuple(template.trust_levels) != tuple(expected.trust_levels)
                                 or tuple(template.incident_types) != tuple(expected.incident_types)):
        raise InputError(str(study_dir / MANIFEST_FILE), "config.driver_model",
                         f"the pilot's trust levels {list(template.trust_levels)} / incidents "
                         f"{list(template.incident_types)} differ from the planned study's "
                         f"({list(expected.trust_levels)} / {list(expected.incident_types)})",
                         "plan from a pilot run with the driver model of the config you plan")
    return manifest, episodes, roads, template


def fit_pilot(study_dir: Path, resamples: int, rng: np.random.Generator,
              iterations: int = defaults.FIT_ITERATIONS, progress: Callable[[], object] | None = None,
              expected: DriverModel | None = None) -> PilotFit:
    """The point fit of the pilot in `study_dir` and `resamples` refits on its participants drawn
    from `rng` (module docstring); progress() after each refit; `expected`: `check_pilot`'s."""
    study_dir = Path(study_dir)
    _, episodes, roads, template = check_pilot(study_dir, expected)
    point = fit_study(study_dir, method="auto", iterations=iterations)
    refits, converged = [], int(point.converged)
    for result in bootstrap_refits(roads, episodes, template, point.method, iterations, resamples, rng):
        refits.append(result.model())
        converged += bool(result.converged)
        if progress is not None:
            progress()
    accuracy = 1.0 if point.report_accuracy is None else float(point.report_accuracy)
    return PilotFit(source=str(study_dir), participants=int(episodes["participant"].nunique()),
                    episodes=point.episodes, roads=point.transitions,
                    reports=int(roads["reported_trust"].notna().sum()), method=point.method,
                    fitted=point.model(), report_accuracy=accuracy,
                    refits=tuple(refits), converged=converged)
