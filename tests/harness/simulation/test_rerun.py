"""The Rerun recording of an episode, read back with rerun's own reader (rerun.chunk.RrdReader).

rerun-sdk 0.41 has no `rerun.dataframe` module any more; its dataframe access is the chunk API
used here (every chunk as an Arrow record batch) and `ChunkStore.reader` (needs datafusion).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from tests.harness.helpers import INCIDENT_ROUTE, SPECS, FixedRoute, ForcedTakeover
from trustroute.harness.simulation.episode import EpisodeOptions, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.rerun_log import ENTITIES, episode_events
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
    record = run_episode(setup, FixedRoute(INCIDENT_ROUTE), synthetic, "rr", seed=2,
                         options=EpisodeOptions(rrd_path=path, net_path=net))
    reader = rr.chunk.RrdReader(path)
    entities: dict[str, list] = {}
    for chunk in reader.stream().to_chunks():
        entities.setdefault(chunk.entity_path, []).append(chunk)
    blueprint = [c for store in reader.blueprints() for c in reader.stream(store=store).to_chunks()]
    return record, entities, blueprint, spec, path


def _column(chunks, suffix: str) -> tuple[np.ndarray, list]:
    """(times in seconds, values) of the component column ending in `suffix`, over all chunks."""
    times, values = [], []
    for chunk in chunks:
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n.endswith(suffix)]
        if not names or "sim_time" not in batch.schema.names:
            continue
        times.append(batch.column("sim_time").cast(pa.int64()).to_numpy())
        values.extend(batch.column(names[0]).to_pylist())  # one list of instances per row
    order = np.argsort(np.concatenate(times), kind="stable") if times else np.array([], dtype=int)
    return (np.concatenate(times)[order] / NANOS if times else np.array([])), [values[i] for i in order]


def test_every_entity_and_the_waypoints(recorded):
    record, entities, _, spec, _ = recorded
    expected = {f"/{e}" for e in ENTITIES}
    expected |= {f"/world/waypoints/{atom}" for atom in spec.state_atoms}
    expected |= {f"/belief/{name}" for name in spec.belief_atoms}
    expected |= {f"/belief/{name}_threshold" for name in spec.belief_atoms}
    expected |= {f"/world/incidents/{row.index}_{row.incident}" for row in record.incidents.itertuples()}
    assert expected <= set(entities)
    assert all(c.is_static for c in entities["/world/lanes"])
    lanes = entities["/world/lanes"][0].to_record_batch()
    assert len(lanes.column("LineStrips2D:strips")[0]) >= 36  # at least one strip per road
    for atom, roads in spec.state_atoms.items():
        batch = entities[f"/world/waypoints/{atom}"][0].to_record_batch()
        assert len(batch.column("LineStrips2D:strips")[0]) == len(roads)
        labels = entities[f"/world/waypoints/{atom}/label"][0].to_record_batch().column("Points2D:labels")
        assert sorted(labels[0].as_py()) == sorted(f"{atom} ({road})" for road in roads)


def test_blueprint_is_in_the_file(recorded):
    *_, blueprint, _, _ = recorded
    assert blueprint, "no blueprint store in the .rrd"
    paths = {c.entity_path for c in blueprint}
    view_classes = set()
    for chunk in blueprint:
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("class_identifier"):
                view_classes |= {str(v) for cell in batch.column(name).to_pylist() for v in cell or []}
    flat = {str(v) for v in view_classes}
    for view in ("2D", "TimeSeries", "StateTimeline", "BarChart", "TextLog"):
        assert any(view in v for v in flat), (view, flat)
    origins = set()
    for chunk in blueprint:
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("space_origin"):
                origins |= {str(v) for cell in batch.column(name).to_pylist() for v in cell or []}
    assert {"world", "trust", "belief", "state", "events"} <= origins, origins
    assert any(p.startswith("/container") or p.startswith("/view") for p in paths)


def test_ego_logged_at_every_sumo_step(recorded):
    record, entities, *_ = recorded
    times, strips = _column(entities["/world/ego/box"], "LineStrips2D:strips")
    kin = record.kinematics
    np.testing.assert_allclose(times, kin["time"].to_numpy())
    centres = np.array([np.mean(np.asarray(s[0])[[0, 2, 3, 4]], axis=0) for s in strips])
    on_screen = kin[["x", "y"]].to_numpy() * [1, -1]  # Rerun's 2D y points down: the map is logged y-negated
    np.testing.assert_allclose(centres, on_screen, atol=1e-2)
    _, colours = _column(entities["/world/ego/box"], "LineStrips2D:colors")
    manual = (kin["mode"] == "manual").to_numpy()
    assert manual.any() and not manual.all()
    red = np.array([c[0] for c in colours]) == 0xE62828FF  # MANUAL_COLOR as RGBA
    np.testing.assert_array_equal(red, manual)
    trail_times, trails = _column(entities["/world/ego/trail"], "LineStrips2D:strips")
    assert len(kin) / 5 <= len(trails) <= len(kin) and trail_times[-1] == times[-1]
    last = np.asarray(trails[-1][0])[-1]
    np.testing.assert_allclose(last, on_screen[-1], atol=1e-2)


def test_takeover_intervals_and_states(recorded):
    record, entities, *_ = recorded
    times, states = _column(entities["/state/control"], "StateChange:state")
    row = record.incidents[record.incidents["takeover"]].iloc[0]
    assert row.incident == "truck"
    manual_from = times[[s == ["manual"] for s in states]]
    back_at = times[[s == ["autopilot"] for s in states]]
    assert np.any(np.abs(manual_from - row.takeover_start) <= 0.5 + 1e-9)
    assert np.any(np.abs(back_at - row.takeover_end) <= 0.5 + 1e-9)
    _, roads = _column(entities["/state/road"], "StateChange:state")
    assert [r[0] for r in roads] == list(record.roads["directed_road"])
    for row in record.incidents.itertuples():
        times, _ = _column(entities[f"/world/incidents/{row.index}_{row.incident}"], "Boxes2D:centers")
        np.testing.assert_allclose(times, [row.injected_time])


def _assert_belief_series(entities, belief: np.ndarray, spec) -> None:
    """The recording's belief mean, P(trust >= 6) and belief atoms are those of `belief` (rows:
    the logged trust beliefs, one per road)."""
    _, mean = _column(entities["/trust/belief_mean"], "Scalars:scalars")
    np.testing.assert_allclose(np.ravel(mean), belief @ np.arange(1, 8))
    _, high = _column(entities["/belief/p_trust_ge_6"], "Scalars:scalars")
    np.testing.assert_allclose(np.ravel(high), belief[:, 5:].sum(axis=1))
    for name, atom in spec.belief_atoms.items():
        _, values = _column(entities[f"/belief/{name}"], "Scalars:scalars")
        np.testing.assert_allclose(np.ravel(values), belief @ np.asarray(atom.coeffs))


def test_every_trust_and_belief_series(recorded):
    record, entities, _, spec, _ = recorded
    roads = record.roads
    n = len(roads)
    _, true = _column(entities["/trust/true"], "Scalars:scalars")
    true = [v[0] for v in true]
    np.testing.assert_array_equal(true, roads["trust_after"].to_numpy(dtype=float))
    belief = np.array(roads["belief_after"].tolist())
    _assert_belief_series(entities, belief, spec)
    for name, atom in spec.belief_atoms.items():
        _, threshold = _column(entities[f"/belief/{name}_threshold"], "Scalars:scalars")
        assert np.ravel(threshold).tolist() == [atom.offset] * n
    reported = roads["reported_trust"].to_numpy()
    _, logged = _column(entities["/trust/reported"], "Scalars:scalars")
    np.testing.assert_array_equal(np.ravel(logged), reported[reported >= 1])
    _, bars = _column(entities["/belief/distribution"], "BarChart:values")
    assert len(bars) == n
    _, dfa = _column(entities["/state/dfa"], "StateChange:state")
    assert dfa[0] == [f"q{roads['dfa_state'].iloc[0]}"]


def test_event_log(recorded):
    record, entities, *_ = recorded
    times, texts = _column(entities["/events"], "TextLog:text")
    expected = episode_events(record)
    texts = [t[0] for t in texts]
    assert [t for _, _, t in expected] == texts
    np.testing.assert_allclose(times, [t for t, _, _ in expected])
    joined = "\n".join(texts)
    for road in record.roads["directed_road"]:
        assert f"entered: {road}" in joined
    assert "truck in view" in joined and "takeover on road" in joined and "hand-back" in joined
    assert texts[-1].startswith("episode ends") or texts[-1] == "spec accepted"


def test_recording_is_small(recorded):
    record, *_, path = recorded
    # A few kilobytes of map plus a few hundred bytes per SUMO step.
    # Measured: about 230 kB for this 210 s episode (420 steps), most of it per-chunk Arrow metadata.
    assert path.stat().st_size < 300_000 + 200 * len(record.kinematics)


def test_the_map_is_the_right_way_up_and_scaled_to_the_town(recorded, town):
    from trustroute.harness.simulation.rerun_log import JUNCTION_RADIUS
    from trustroute.networks.town_map import map_frame

    _, entities, *_ = recorded
    batch = entities["/world/junctions"][0].to_record_batch()
    names = batch.column("Points2D:labels")[0].as_py()
    positions = np.asarray(batch.column("Points2D:positions")[0].as_py())
    # Rerun's 2D y points down: A (north of E in the town file) must be drawn above E, at smaller y.
    np.testing.assert_allclose(positions, [[town.junctions[n][0], -town.junctions[n][1]] for n in names],
                               atol=1e-3)
    assert positions[names.index("A")][1] < positions[names.index("E")][1]
    radius = batch.column("Points2D:radii")[0].as_py()[0]
    assert radius == pytest.approx(JUNCTION_RADIUS * map_frame(town).unit, rel=1e-6)
    assert radius < 9.0  # smaller than the 9 m markers that hid Town01's 49 m roads' ends


def test_a_road_is_drawn_along_the_towns_geometry_where_it_has_one(town, tmp_path):
    import sumolib

    from trustroute.harness.simulation.rerun_log import road_course
    from trustroute.networks.sumo_net import build_net
    from trustroute.networks.town import town_from_dict

    data = {"junctions": {k: list(v) for k, v in town.junctions.items()},
            "roads": [list(r) for r in town.roads], "incidents": dict(town.incidents)}
    plain = town_from_dict(data, "plain.json")  # Town01 without its geometry
    net = sumolib.net.readNet(str(build_net(plain, cache_dir=tmp_path).path))
    lane = road_course(net, plain, "B-C")  # no geometry entry: the net's lane
    np.testing.assert_allclose(lane, net.getEdge("B-C").getLanes()[-1].getShape(), atol=1e-4)
    bent = [[89.68, -4.9], [0.0, 0.0], [0.0, -328.0], [91.5, -324.06]]
    shaped = town_from_dict({**data, "geometry": {"A-E": {"shape": bent}}}, "shaped.json")
    np.testing.assert_allclose(road_course(net, shaped, "A-E"), bent, atol=1e-4)
    # The default town's outer street, not the net's straight edge beside the inner street.
    np.testing.assert_allclose(road_course(net, town, "A-E"), town.geometry["A-E"].shape, atol=1e-4)
    assert road_course(net, town, "A-E")[:, 0].min() < 1.0 < 80.0 < net.getEdge("A-E").getShape()[0][0]


def test_time_views_open_on_the_whole_episode(tmp_path):
    """The trust, belief and state views' horizontal axes open on the whole timeline (infinite
    view range), not on a window at the end of the episode."""
    import rerun as rr

    from trustroute.harness.simulation.rerun_log import episode_blueprint

    path = tmp_path / "blueprint.rrd"
    rec = rr.RecordingStream("trustroute-blueprint-test")
    rec.save(str(path), default_blueprint=episode_blueprint())
    rec.flush()
    reader = rr.chunk.RrdReader(path)
    chunks = [c for store in reader.blueprints() for c in reader.stream(store=store).to_chunks()]
    kinds = []  # per view range: the union variant of its start and end boundaries
    for chunk in chunks:
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if "TimeAxis:view_range" not in name:
                continue
            ranges = batch.column(name).values
            for side in ("start", "end"):
                union = ranges.field(side)
                kinds += [union.type.field(int(code)).name for code in union.type_codes.to_pylist()]
    assert len(kinds) == 6, kinds  # trust, belief and state views, start and end each
    assert set(kinds) == {"Infinite"}, kinds


def test_a_type_aware_avs_episode_is_recorded_on_its_trust_marginal(town, net_path, tmp_path):
    """The `robust` condition's AV filters over (type, trust): the roads table logs its trust
    marginal, and the recording's trust and belief series read that marginal with the base trust
    levels and the spec's own coefficients."""
    import rerun as rr

    from trustroute.participants.driver_population import load_driver_population
    from trustroute.policies.belief.driver_types import lift_population, lift_spec

    population = load_driver_population("driver_population_three_types")
    spec = load_spec(SPECS / "phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=lift_population(population),
                         spec=lift_spec(spec, population), fallback_after=None)
    synthetic = SyntheticDriver(population.types[0].model, np.random.default_rng(3), initial_trust=4)
    path = tmp_path / "robust.rrd"
    record = run_episode(setup, FixedRoute(INCIDENT_ROUTE), synthetic, "rr-robust", seed=2,
                         options=EpisodeOptions(rrd_path=path, net_path=net_path))
    belief = np.array(record.roads["belief_after"].tolist())
    assert belief.shape[1] == 7
    entities: dict[str, list] = {}
    for chunk in rr.chunk.RrdReader(path).stream().to_chunks():
        entities.setdefault(chunk.entity_path, []).append(chunk)
    _assert_belief_series(entities, belief, spec)
    from trustroute.harness.simulation.rerun_log import marginal_coefficients

    # a type-belief atom (1 on the first type's block) has no value on the trust marginal
    assert marginal_coefficients(np.repeat([1.0, 0.0, 0.0], 7), 7) is None
