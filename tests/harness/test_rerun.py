"""The Rerun recording of an episode, read back with rerun's own API."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from tests.harness.helpers import INCIDENT_ROUTE, SPECS, FixedRoute, ForcedTakeover
from trustroute.harness.episode import run_episode
from trustroute.harness.episode_tracker import EpisodeSetup
from trustroute.networks.sumo_net import build_net
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec

NANOS = 1e9


@pytest.fixture(scope="module")
def recorded(town, driver, tmp_path_factory):
    import rerun as rr

    directory = tmp_path_factory.mktemp("rrd")
    net = build_net(town, cache_dir=directory).path
    spec = load_spec(SPECS / "phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec, fallback_after=None)
    synthetic = ForcedTakeover(SyntheticDriver(driver, np.random.default_rng(1), initial_trust=4), ("truck",))
    path = directory / "episode.rrd"
    record = run_episode(setup, FixedRoute(INCIDENT_ROUTE), synthetic, "rr", seed=2, rrd_path=path,
                         net_path=net)
    chunks = rr.chunk.RrdReader(path).stream().to_chunks()
    entities: dict[str, list] = {}
    for chunk in chunks:
        entities.setdefault(chunk.entity_path, []).append(chunk)
    return record, entities


def _times(chunks) -> np.ndarray:
    batches = [c.to_record_batch() for c in chunks if "sim_time" in c.timeline_names]
    values = pa.concat_arrays([b.column("sim_time").cast(pa.int64()) for b in batches])
    return np.sort(values.to_numpy()) / NANOS


def test_entities_present(recorded):
    record, entities = recorded
    expected = {"/world/lanes", "/world/junctions", "/world/ego", "/episode/takeover", "/episode/trust/true",
                "/episode/trust/reported", "/episode/belief/mean", "/episode/dfa_state", "/episode/roads"}
    expected |= {f"/episode/belief/p{level}" for level in range(1, 8)}
    expected |= {f"/world/incidents/{row.index}_{row.incident}" for row in record.incidents.itertuples()}
    assert expected <= set(entities)
    assert all(c.is_static for c in entities["/world/lanes"])
    lanes = entities["/world/lanes"][0].to_record_batch()
    assert len(lanes.column("LineStrips2D:strips")[0]) >= 36   # at least one strip per road


def test_time_ranges(recorded):
    record, entities = recorded
    ego = _times(entities["/world/ego"])
    kin = record.kinematics["time"].to_numpy()
    assert len(ego) == len(kin)
    np.testing.assert_allclose([ego[0], ego[-1]], [kin[0], kin[-1]])
    trust = _times(entities["/episode/trust/true"])
    assert len(trust) == len(record.roads)
    assert trust[-1] <= record.summary["sim_seconds"] + 1e-9
    takeover = _times(entities["/episode/takeover"])
    row = record.incidents[record.incidents["takeover"]].iloc[0]
    assert row.incident == "truck"
    assert row.takeover_start in takeover and row.takeover_end in takeover
    for row in record.incidents.itertuples():
        times = _times(entities[f"/world/incidents/{row.index}_{row.incident}"])
        np.testing.assert_allclose(times, [row.injected_time, row.removed_time])
