"""Fitting drivers on real-study-shaped logs: regularised takeover probabilities, EM convergence
reporting, the participant bootstrap, and the posterior-predictive check's distances.

Data are simulated from a known model on the real study's own roads (the committed conversion),
so the checks can fail: a wrong model must be measurably farther than the true one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trustroute.analysis.fitting.driver_model import bootstrap_fit, fit_roads, regularised_takeover
from trustroute.analysis.fitting.posterior_check import real_arrays
from trustroute.app.drivers import simulate
from trustroute.app.runs import posterior_check
from trustroute.core.dataset import read_episodes, read_roads
from trustroute.participants.driver_model import driver_model_from_dict, load_driver_model

STUDY = Path(__file__).resolve().parents[3] / "analysis" / "data" / "real_study" / "study"


@pytest.fixture(scope="module")
def real_roads() -> pd.DataFrame:
    return read_roads(STUDY)


def simulated_roads(roads: pd.DataFrame, model, replicates: int, seed: int) -> pd.DataFrame:
    """Roads tables of `model`'s drivers on the real roads (exact reports: accuracy 1)."""
    incident, _, _, mask = real_arrays(roads, model)
    simulated = simulate(model, incident, mask, 1.0, replicates, np.random.default_rng(seed))
    take, failed, report = simulated.takeover, simulated.failed, simulated.report
    incident, mask = np.repeat(incident, replicates, axis=0), np.repeat(mask, replicates, axis=0)
    rows = []
    for e in range(mask.shape[0]):
        k = int(mask[e].sum())
        rows.append(
            {
                "episode_id": f"s{e:05d}",
                "index": 0,
                "incident": "none",
                "takeover": None,
                "performance": None,
                "reported_trust": int(report[e, 0]),
            }
        )
        for t in range(k):
            rows.append(
                {
                    "episode_id": f"s{e:05d}",
                    "index": t + 1,
                    "incident": model.incident_types[incident[e, t]],
                    "takeover": bool(take[e, t]),
                    "performance": "fail" if failed[e, t] else "succ",
                    "reported_trust": int(report[e, t + 1]),
                }
            )
    frame = pd.DataFrame(rows)
    frame["takeover"] = frame["takeover"].astype("boolean")
    return frame


def test_regularised_takeover_is_never_zero_or_one_unless_the_incident_is_never_taken_over():
    taken = np.array([[0.0, 3.0, 0.0], [0.0, 0.0, 0.0]])
    visits = np.array([[10.0, 3.0, 0.0], [4.0, 4.0, 4.0]])
    previous = np.array([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]])
    p = regularised_takeover(taken, visits, previous)
    assert (p[0] > 0).all() and (p[0] < 1).all()
    pooled = (3 + 1) / (13 + 2)
    assert p[0, 2] == pytest.approx(pooled)  # an unvisited level takes its incident's pooled rate
    assert (p[1] == 0).all()  # structural zero: never taken over


def test_em_says_whether_it_converged(real_roads):
    driver = load_driver_model(None)
    roads = simulated_roads(real_roads, driver, 2, seed=3)
    capped = fit_roads(roads, driver, "em", iterations=2)
    assert capped.converged is False and capped.summary()["converged"] is False
    full = fit_roads(roads, driver, "em", iterations=300)
    assert full.converged is True and full.iterations < 300


def test_fitted_takeover_probabilities_are_not_absurd_on_real_logs(real_roads):
    driver = load_driver_model(None)
    result = fit_roads(real_roads, driver, "em", iterations=300)
    taken_over = result.parameters.takeover[result.parameters.takeover.any(axis=1)]
    assert taken_over.min() > 1e-4 and taken_over.max() < 1 - 1e-4
    assert result.converged


def test_participant_bootstrap_is_seeded_and_ordered(real_roads):
    driver = load_driver_model(None)
    episodes = read_episodes(STUDY)
    keep = set(episodes[episodes["participant"].isin([1, 3, 4, 6, 7])]["episode_id"])
    roads = real_roads[real_roads["episode_id"].isin(keep)]
    part = episodes[episodes["episode_id"].isin(keep)]
    a = bootstrap_fit(roads, part, driver, "em", 50, 3, np.random.default_rng(5))
    b = bootstrap_fit(roads, part, driver, "em", 50, 3, np.random.default_rng(5))
    assert a == b
    for bounds in a["takeover_probability"].values():
        assert (np.array(bounds["low"]) <= np.array(bounds["high"]) + 1e-12).all()
    assert a["resamples"] == 3 and 0 <= a["converged"] <= 3


@pytest.mark.slow
def test_check_puts_the_true_model_nearer_than_a_wrong_one(real_roads):
    driver = load_driver_model(None)
    observed = simulated_roads(real_roads, driver, 100, seed=11)
    wrong_dict = driver.to_dict()
    wrong_dict["takeover_probability"] = {
        k: [min(1.0, 2.5 * x) for x in v] for k, v in wrong_dict["takeover_probability"].items()
    }
    wrong = driver_model_from_dict(wrong_dict, "wrong")
    check = posterior_check(
        observed, {"true": (driver, 1.0), "wrong": (wrong, 1.0)}, 10, np.random.default_rng(12)
    )
    true_d, wrong_d = check["models"]["true"]["distance"], check["models"]["wrong"]["distance"]
    # stated tolerances: 7700 observed episodes, 10 replicates each; the rarest incident (obstacle,
    # 18 real roads, 1800 observed) has a standard error of about 0.009 on its rate difference
    assert max(true_d["takeover_rate_abs_difference"].values()) < 0.03
    assert true_d["trust_change_tv"] < 0.05 and true_d["final_trust_tv"] < 0.06
    assert max(wrong_d["takeover_rate_abs_difference"].values()) > 3 * max(
        true_d["takeover_rate_abs_difference"].values()
    )
