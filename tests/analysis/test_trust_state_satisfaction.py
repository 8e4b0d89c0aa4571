"""Trust-state atoms in the analysis: simulated logs are read on the true trust, real logs on the
reported trust as θ; both agree with the episode tracker's own verdict where they must."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from trustroute.analysis.satisfaction import episode_satisfaction
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import run_model_episode
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import trust_free_policy


def _episodes(town, driver, spec, report_accuracy: float, count: int = 40):
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    policy = trust_free_policy(town, spec)
    summaries, roads = [], []
    for n in range(count):
        synthetic = SyntheticDriver(driver, np.random.default_rng(100 + n), report_accuracy=report_accuracy)
        record = run_model_episode(setup, policy, synthetic, f"e{n}", n)
        summaries.append({**record.summary, "spec": spec.name})
        roads.append(record.roads)
    return pd.DataFrame(summaries), pd.concat(roads, ignore_index=True)


def test_simulated_logs_are_read_on_the_true_trust_as_the_tracker_decided(town, driver):
    spec = load_spec("specs/phi1_trust.toml", town)
    episodes, roads = _episodes(town, driver, spec, report_accuracy=0.0)
    result = episode_satisfaction(roads, episodes, {spec.name: spec}, town, driver.trust_levels)
    assert result["satisfied"].tolist() == episodes["satisfied"].tolist()
    assert 0 < episodes["satisfied"].sum() < len(episodes)        # both outcomes occur
    # Reports that are always one level off (accuracy 0) stand in for θ differently somewhere.
    reported = episode_satisfaction(roads, episodes, {spec.name: spec}, town, driver.trust_levels,
                                    trust_source="reported")
    assert reported["satisfied"].tolist() != episodes["satisfied"].tolist()


def test_exact_reports_read_as_theta_give_the_true_trust_verdict(town, driver):
    """phi1_trust reads the trust only after the start road, where an exact report is the trust."""
    spec = load_spec("specs/phi1_trust.toml", town)
    episodes, roads = _episodes(town, driver, spec, report_accuracy=1.0)
    reported = episode_satisfaction(roads, episodes, {spec.name: spec}, town, driver.trust_levels,
                                    trust_source="reported")
    assert reported["satisfied"].tolist() == episodes["satisfied"].tolist()


def test_logs_without_any_report_cannot_stand_in_for_theta(town, driver):
    spec = load_spec("specs/phi1_trust.toml", town)
    episodes, roads = _episodes(town, driver, spec, report_accuracy=1.0, count=2)
    with pytest.raises(ValueError, match="no trust report"):
        episode_satisfaction(roads.assign(reported_trust=None), episodes, {spec.name: spec}, town,
                             driver.trust_levels, trust_source="reported")
