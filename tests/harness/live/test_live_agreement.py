"""Without lockstep, scripted participants drive live at their own pace, as people do: their
takeovers reach the episode when they arrive, not at the decision. The study's figures then agree
with `trustroute study` on the same config and seeds within statistical tolerance (exact agreement
is the lockstep test's, tests/harness/live/test_live_episode.py)."""

from __future__ import annotations

import threading

import httpx
import numpy as np
import pytest
from scipy import stats

from trustroute.core.dataset import read_episodes
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.runner import run_and_consolidate

from .conftest import tiny_config
from .test_live_episode import serving

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]

PARTICIPANTS = 12
AT_ONCE = 4          # participants connected at the same time (the machine has 2 cores)
PACE = 20.0          # sim seconds per wall second: reactions arrive while the ego drives on
SIGNIFICANCE = 0.01  # a difference this unlikely under "same figures" fails the test


def live_study(config, study_dir):
    study = LiveStudy(config, study_dir, ServerOptions(pace=PACE, warm_up=False)).open()
    try:
        with serving(study) as address:
            headers = {"Authorization": f"Bearer {study.experimenter_token}"}
            players = [ScriptedParticipant(config, p) for p in range(config.participants)]
            tokens = [httpx.post(f"http://{address}/api/participants", json={}, headers=headers)
                      .json()["token"] for _ in players]
            url, pairs = f"ws://{address}/ws", list(zip(tokens, players, strict=True))
            for first in range(0, len(players), AT_ONCE):
                threads = [threading.Thread(target=run_scripted, args=(url, token, player, 300))
                           for token, player in pairs[first:first + AT_ONCE]]
                for each in threads:
                    each.start()
                for each in threads:
                    each.join(600)
        assert all(player.finished for player in players)
        # every drive ran once, to its end: a trial run again after a failed attempt still leaves
        # every part, so only this shows a drive that stood until max_sim_seconds
        ends = [record for record in study.attempts.records() if record["event"] == "end"]
        assert [record for record in ends if record["outcome"] != "done"] == []
        assert [e for player in players for e in player.errors if e["code"] != "out_of_order"] == []
    finally:
        study.close()


def test_live_figures_agree_with_the_headless_study_within_statistical_tolerance(tmp_path):
    config = tiny_config(tmp_path, participants=PARTICIPANTS, specs=("phi1", "phi2"))
    run_and_consolidate(config.with_overrides(engine="sumo"), tmp_path / "headless", 1, None, progress=False,
                        echo=lambda line: None)
    live_study(config, tmp_path / "live")
    headless = read_episodes(tmp_path / "headless").set_index("episode_id").sort_index()
    live = read_episodes(tmp_path / "live").set_index("episode_id").sort_index()
    assert list(live.index) == list(headless.index)   # every planned episode, once
    assert headless["takeovers"].sum() > 0 and live["takeovers"].sum() > 0
    satisfied = [[int(frame["satisfied"].sum()), int((~frame["satisfied"].astype(bool)).sum())]
                 for frame in (headless, live)]
    assert stats.fisher_exact(satisfied).pvalue >= SIGNIFICANCE, satisfied
    for column in ("mean_reported_trust", "takeovers", "junctions"):
        both = headless[column].notna() & live[column].notna()   # paired by episode (same seeds)
        pair = [frame.loc[both, column].astype(float).to_numpy() for frame in (headless, live)]
        if np.array_equal(pair[0], pair[1]):
            continue   # identical figures: nothing to test (a t test is undefined on zero variance)
        assert stats.ttest_rel(*pair).pvalue >= SIGNIFICANCE, (column, pair)
