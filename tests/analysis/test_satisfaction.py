"""Satisfaction re-evaluated from logs: the filter source reproduces what the episodes logged;
the reported source builds point-mass beliefs from reports."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from trustroute.analysis.satisfaction import episode_satisfaction, reported_beliefs
from trustroute.analysis.study_directory import load_study, study_inputs
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import baseline_route


@pytest.mark.slow
def test_filter_source_reproduces_logged_satisfaction(model_study):
    manifest, episodes, roads = load_study(model_study)
    town, driver, specs = study_inputs(manifest, model_study)
    result = episode_satisfaction(roads, episodes, specs, town, driver.trust_levels, "filter")
    assert list(result["episode_id"]) == list(episodes["episode_id"])
    assert (result["satisfied"].to_numpy() == episodes["satisfied"].to_numpy()).all()
    # accepted episodes end exactly at their first accepting position
    accepted = episodes["end_reason"].to_numpy() == "accepted"
    assert (
        result["first_accepting"].to_numpy()[accepted] == episodes["junctions"].to_numpy()[accepted]
    ).all()


def test_reported_beliefs_carry_the_last_report_forward():
    k = 7
    filter_beliefs = np.full((1, 5, k), 1 / k)
    reports = np.array([[-1, 7, -1, 3, -1]])
    out = reported_beliefs(filter_beliefs, reports, tuple(range(1, 8)))
    assert np.allclose(out[0, 0], 1 / k)
    assert out[0, 1, 6] == 1 and out[0, 2, 6] == 1
    assert out[0, 3, 2] == 1 and out[0, 4, 2] == 1
    assert np.allclose(out.sum(axis=2), 1)


def _trace(town, route, reports, spec_name):
    rows = []
    uniform = [1 / 7] * 7
    for i, road in enumerate(route):
        rows.append(
            {
                "episode_id": "e",
                "index": i,
                "directed_road": road,
                "belief_after": uniform,
                "reported_trust": reports[i],
            }
        )
    roads = pd.DataFrame(rows)
    episodes = pd.DataFrame({"episode_id": ["e"], "spec": [spec_name]})
    return roads, episodes


@pytest.mark.parametrize("last_report, expected", [(7, True), (6, True), (5, False)])
def test_reported_source_decides_hightrust_at_the_last_waypoint(town, driver, last_report, expected):
    spec = load_spec("specs/phi1.toml", town)
    route = baseline_route(town, spec)
    reports = [-1] + [4] * (len(route) - 2) + [last_report]
    roads, episodes = _trace(town, route, reports, "phi1")
    specs = {"phi1": spec}
    reported = episode_satisfaction(roads, episodes, specs, town, driver.trust_levels, "reported")
    assert bool(reported["satisfied"].iloc[0]) is expected
    # the uniform filter belief never has P(θ >= 6) > 0.5
    filtered = episode_satisfaction(roads, episodes, specs, town, driver.trust_levels, "filter")
    assert not bool(filtered["satisfied"].iloc[0])
