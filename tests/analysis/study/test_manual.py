"""The manual-driving table: per incident type and condition, from the incidents' takeover rows."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from trustroute.analysis.formatting import MISSING
from trustroute.analysis.study.manual import manual_display, manual_table


def test_the_measures_are_summarised_per_incident_type_and_condition():
    nan = math.nan
    incidents = pd.DataFrame([
        # episode, incident, reaction, lateral SD, min TTC, max decel, oncoming s, departures, collisions
        ("e1", "obstacle", 1.0, 0.2, 3.0, 4.0, 5.0, 0, 0),
        ("e2", "obstacle", 2.0, 0.4, 1.5, 6.0, 7.0, 1, 1),
        ("e3", "obstacle", 3.0, nan, nan, nan, nan, None, None),   # assisted: the reaction only
        ("e1", "pedestrian", 0.5, 0.1, math.inf, 2.0, 0.0, 0, 0),
    ], columns=["episode_id", "incident", "takeover_reaction", "lateral_sd", "manual_min_ttc",
                "manual_max_deceleration", "oncoming_seconds", "road_departures", "collisions"])
    incidents["takeover"] = True
    episodes = pd.DataFrame({"episode_id": ["e1", "e2", "e3"], "condition": ["free", "aware", "aware"]})
    table = manual_table(incidents, episodes, ["aware", "free"])
    rows = {(r.incident, r.condition): r for r in table.itertuples()}
    aware = rows[("obstacle", "aware")]
    assert (aware.takeovers, aware.by_wheel) == (2, 1)
    assert aware.reaction_s == pytest.approx(2.5)          # (2 + 3) / 2: every takeover
    measured = (aware.lateral_sd_m, aware.min_ttc_s, aware.max_deceleration, aware.oncoming_s)
    assert measured == (0.4, 1.5, 6.0, 7.0)   # the one takeover by wheel
    assert (aware.road_departures, aware.collisions) == (1, 1)
    free = rows[("obstacle", "free")]
    assert (free.takeovers, free.reaction_s, free.lateral_sd_m, free.road_departures) == (1, 1.0, 0.2, 0)
    assert list(table["condition"][:2]) == ["aware", "free"]   # the study's order within an incident
    shown = manual_display(table)
    assert shown.loc[2, "min TTC (s)"] == "inf" and shown.loc[0, "SD lateral (m)"] == "0.40"
    assert len(manual_table(incidents.iloc[0:0], episodes, ["aware"])) == 0
    # a group of assisted takeovers only has no wheel measures: shown as every table shows a missing figure
    assisted = manual_display(manual_table(incidents.iloc[2:3], episodes, ["aware"])).iloc[0]
    assert (assisted["reaction (s)"], assisted["by wheel"]) == ("3.00", 0)
    assert [assisted[c] for c in ("SD lateral (m)", "min TTC (s)", "max decel (m/s²)", "oncoming (s)")] == [
        MISSING] * 4
