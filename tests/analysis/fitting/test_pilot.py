"""A pilot study fitted for `trustroute plan --pilot` (analysis/fitting/pilot.py): the point fit is
the one `trustroute fit` makes, the refits are seeded and differ from one another (the fit's
uncertainty), and a study that cannot be fitted is refused with the file, the place and the fix."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from trustroute.analysis.fitting.driver_model import fit_study
from trustroute.analysis.fitting.pilot import MIN_PILOT_PARTICIPANTS, fit_pilot
from trustroute.core.errors import InputError


@pytest.mark.slow  # a pilot study of 8 participants (seconds), shared with the plan tests
def test_the_pilot_is_fitted_by_fit_and_its_refits_are_seeded(pilot_study):
    pilot = pilot_study(7)
    fit = fit_pilot(pilot, 6, np.random.default_rng(3))
    assert fit.fitted.content_hash == fit_study(pilot).model().content_hash   # the fit `trustroute fit` makes
    assert (fit.participants, fit.episodes, fit.method, len(fit.refits)) == (8, 32, "counts", 6)
    assert fit.reports > 0 and fit.report_accuracy == 1.0
    again = fit_pilot(pilot, 6, np.random.default_rng(3))
    hashes = [m.content_hash for m in fit.refits]
    assert hashes == [m.content_hash for m in again.refits]                 # same seed, same refits
    assert len(set(hashes)) == 6 and fit.fitted.content_hash not in hashes   # resamples differ
    assert "8 participants" in fit.label() and "6 bootstrap refits" in fit.label()
    alone = fit_pilot(pilot, 0, np.random.default_rng(3))
    assert alone.models == (alone.fitted,) and "uncertainty not drawn" in alone.label()
    other = dataclasses.replace(fit.fitted, incident_types=("rain", *fit.fitted.incident_types[1:]))
    with pytest.raises(InputError) as error:   # refused before any fit
        fit_pilot(pilot, 2, np.random.default_rng(3), expected=other)
    assert error.value.place == "config.driver_model" and "rain" in str(error.value)


def test_a_study_directory_is_required(tmp_path):
    with pytest.raises(InputError) as error:
        fit_pilot(tmp_path, 2, np.random.default_rng(0))
    assert "manifest.json" in str(error.value) and "fix:" in str(error.value)


@pytest.mark.slow
def test_too_few_participants_or_no_reports_are_refused(pilot_study):
    # two small studies of their own (a few seconds on a loaded machine)
    few = pilot_study(2, participants=MIN_PILOT_PARTICIPANTS - 1)
    with pytest.raises(InputError) as error:
        fit_pilot(few, 2, np.random.default_rng(0))
    assert error.value.place == "participant" and error.value.source.endswith("episodes.parquet")
    silent = pilot_study(2, participants=MIN_PILOT_PARTICIPANTS, extra="report_every = 10000")
    with pytest.raises(InputError) as error:
        fit_pilot(silent, 2, np.random.default_rng(0))
    assert error.value.place == "reported_trust" and error.value.source.endswith("roads.parquet")
