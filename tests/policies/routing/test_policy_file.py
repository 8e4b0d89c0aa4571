"""Policy files: round trip, hash checks (town, driver model, spec), damaged files, resolve, CLI."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from tests.cli import run_cli
from trustroute.core.errors import InputError
from trustroute.networks.town import DEFAULT_TOWN_PATH, town_from_dict
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.resolve import aware_cache_path, resolve_policy
from trustroute.policies.routing.files import array_path, load_policy, read_policy_document, save_policy
from trustroute.policies.routing.protocol import DecisionContext
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.settings import SynthesisSettings


@pytest.fixture(scope="module")
def phi1_result(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    return spec, synthesize(pomdp, spec, SynthesisSettings(horizon=8))


def test_round_trip_keeps_every_decision_and_the_value(pomdp, driver, phi1_result, tmp_path):
    spec, result = phi1_result
    path = save_policy(result, tmp_path / "phi1.json", pomdp.town, driver, spec)
    document = json.loads(path.read_text())
    assert document["lower"] == result.lower and document["horizon"] == 8
    assert document["spec_hash"] == spec.content_hash
    loaded = load_policy(path, pomdp.town, driver, spec)
    for name in ("t", "x", "q", "beliefs", "action"):
        assert np.array_equal(getattr(loaded.table, name), getattr(result.policy.table, name))
    rng = np.random.default_rng(0)
    for _ in range(100):
        road = str(rng.choice(pomdp.town.states))
        context = DecisionContext(route=("E-A",) * int(rng.integers(10)) + (road,),
                                  dfa_state=int(rng.integers(4)), belief=rng.dirichlet(np.ones(7)))
        assert loaded.next_junction(context) == result.policy.next_junction(context)
    value = evaluate(pomdp, spec, loaded, EvaluationSettings(fallback_after=None, max_junctions=8))
    assert value.lower == pytest.approx(result.lower, abs=1e-12)


def test_another_town_driver_or_spec_is_a_clear_error(pomdp, town, driver, phi1_result, tmp_path):
    spec, result = phi1_result
    path = save_policy(result, tmp_path / "phi1.json", town, driver, spec)
    other_spec = load_spec("specs/phi2.toml", town)
    other_driver = replace(driver, initial_belief=np.r_[0.4, np.full(6, 0.1)])
    data = json.loads(DEFAULT_TOWN_PATH.read_text())
    data["incidents"]["A-F"] = "truck"
    other_town = town_from_dict(data, "<edited town>")
    for args, word in (((town, driver, other_spec), "spec"), ((town, other_driver, spec), "driver"),
                       ((other_town, driver, spec), "town")):
        with pytest.raises(InputError) as error:
            load_policy(path, *args)
        message = error.value.one_line()
        assert str(path) in message and f"another {word}" in message and "trustroute synth" in message


def test_damaged_files_are_input_errors(town, driver, phi1_result, tmp_path):
    spec, result = phi1_result
    path = save_policy(result, tmp_path / "p.json", town, driver, spec)
    arrays = array_path(path)
    arrays.write_bytes(arrays.read_bytes()[:-3] + b"xyz")
    with pytest.raises(InputError, match="does not match"):
        load_policy(path, town, driver, spec)
    arrays.unlink()
    with pytest.raises(InputError, match="missing"):
        load_policy(path, town, driver, spec)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match="not valid JSON"):
        load_policy(tmp_path / "bad.json", town, driver, spec)
    (tmp_path / "other.json").write_text('{"format": "something else"}')
    with pytest.raises(InputError, match="not a trustroute policy file"):
        load_policy(tmp_path / "other.json", town, driver, spec)


@pytest.mark.parametrize("horizon", ["twenty", 20.0, True, -1, 10_001, [20]])
def test_a_horizon_that_is_not_a_junction_count_is_refused(town, driver, phi1_result, tmp_path, horizon):
    spec, result = phi1_result
    path = save_policy(result, tmp_path / "p.json", town, driver, spec)
    document = json.loads(path.read_text())
    assert document["horizon"] == 8
    for good in (0, 8, None):
        path.write_text(json.dumps({**document, "horizon": good}))
        assert read_policy_document(path)["horizon"] == good
    path.write_text(json.dumps({**document, "horizon": horizon}))
    with pytest.raises(InputError) as error:
        load_policy(path, town, driver, spec)
    assert error.value.place == "horizon" and "is not a junction count or null" in error.value.problem


def test_version_2_files_are_refused_with_the_reason(town, driver, phi1_result, tmp_path):
    """Version 2 policies were certified for the state-only completion at rows they lack; this
    acting rule drives the free completion there, so they are refused (one line, the fix named).
    Joint-belief files, whose rule does not use the completion, are still read from version 2 on."""
    spec, result = phi1_result
    path = save_policy(result, tmp_path / "p.json", town, driver, spec)
    document = json.loads(path.read_text())
    assert document["version"] == 4 and "back to what the DFA still needs" in document["acting_rule"]
    path.write_text(json.dumps({**document, "version": 2}))
    with pytest.raises(InputError) as error:
        load_policy(path, town, driver, spec)
    message = error.value.one_line()
    assert "version 2" in message and "state-only completion" in message
    assert "re-run trustroute synth" in message
    joint = {**document, "version": 2, "kind": "joint-belief", "guide_horizon": 8}
    path.write_text(json.dumps(joint))
    assert read_policy_document(path)["version"] == 2
    path.write_text(json.dumps({**joint, "version": 1}))
    with pytest.raises(InputError, match="version 1"):
        read_policy_document(path)


def test_the_npz_given_as_the_policy_names_the_json_beside_it(town, driver, phi1_result, tmp_path):
    spec, result = phi1_result
    path = save_policy(result, tmp_path / "p.json", town, driver, spec)
    with pytest.raises(InputError) as error:
        read_policy_document(array_path(path))
    assert error.value.source == str(array_path(path))
    assert "a policy's decision table (its .npz array file), not the policy file" in error.value.problem
    assert error.value.fix.startswith(f"pass the policy file {path} ")
    moved = tmp_path / "moved.npz"
    array_path(path).rename(moved)
    with pytest.raises(InputError) as error:
        load_policy(moved, town, driver, spec)
    assert "UTF-8" not in error.value.one_line() and "pass the policy's .json file" in error.value.fix


def _rewrite_arrays(path, document: dict, arrays: dict) -> None:
    """Replace a policy file's .npz by `arrays` and record its hash in the document."""
    import hashlib
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    array_path(path).write_bytes(buffer.getvalue())
    path.write_text(json.dumps({**document, "arrays_sha256": hashlib.sha256(buffer.getvalue()).hexdigest()}))


def test_cluster_policy_round_trip_and_damaged_boxes(pomdp, town, driver, tmp_path):
    """A cluster policy (box rows only) survives the file: the same boxes, the same decisions on
    random contexts, and `evaluate` of the loaded policy at least its L; damaged box arrays are one
    line naming the array."""
    spec = load_spec("specs/phi1.toml", town)
    result = synthesize(pomdp, spec, SynthesisSettings(horizon=8, tau=0.05, clusters="on"))
    boxes = result.policy.table.boxes
    assert boxes is not None and boxes.rows > 0 and result.policy.table.rows == 0
    path = save_policy(result, tmp_path / "c.json", town, driver, spec)
    document = json.loads(path.read_text())
    assert document["box_rows"] == boxes.rows
    loaded = load_policy(path, town, driver, spec)
    for name in ("t", "x", "q", "lo", "hi", "value", "action"):
        assert np.array_equal(getattr(loaded.table.boxes, name), getattr(boxes, name))
    rng = np.random.default_rng(1)
    for _ in range(100):
        row = int(rng.integers(boxes.rows))
        belief = boxes.lo[row] + rng.random() * (boxes.hi[row] - boxes.lo[row])
        context = DecisionContext(route=(spec.start,) * int(boxes.t[row]) + (town.states[boxes.x[row]],),
                                  dfa_state=int(boxes.q[row]), belief=belief)
        assert loaded.next_junction(context) == result.policy.next_junction(context)
    value = evaluate(pomdp, spec, loaded, EvaluationSettings(fallback_after=None, max_junctions=8))
    assert value.lower >= result.lower - 1e-9
    with np.load(array_path(path)) as archive:
        arrays = {name: archive[name] for name in archive.files}
    flipped = {**arrays, "box_lo": arrays["box_hi"] + 0.5}
    _rewrite_arrays(path, document, flipped)
    with pytest.raises(InputError) as error:
        load_policy(path, town, driver, spec)
    assert "box_lo" in error.value.one_line() and "re-run trustroute synth" in error.value.one_line()
    _rewrite_arrays(path, document, {k: v for k, v in arrays.items() if k != "box_value"})
    with pytest.raises(InputError, match="box_value"):
        load_policy(path, town, driver, spec)


def test_version_3_files_are_read_without_box_rows(pomdp, town, driver, phi1_result, tmp_path):
    """A version 3 file (no box arrays) loads as a table without box rows and acts as before."""
    spec, result = phi1_result
    path = save_policy(result, tmp_path / "v3.json", town, driver, spec)
    document = json.loads(path.read_text())
    with np.load(array_path(path)) as archive:
        arrays = {name: archive[name] for name in archive.files if not name.startswith("box_")}
    old = {key: value for key, value in document.items() if key != "box_rows"}
    _rewrite_arrays(path, {**old, "version": 3}, arrays)
    loaded = load_policy(path, town, driver, spec)
    assert loaded.table.boxes is None
    value = evaluate(pomdp, spec, loaded, EvaluationSettings(fallback_after=None, max_junctions=8))
    assert value.lower == pytest.approx(result.lower, abs=1e-12)


def test_resolve_free_aware_and_files(pomdp, town, driver, phi1_result, tmp_path, monkeypatch):
    spec, result = phi1_result
    assert resolve_policy("free", town, driver, spec, tmp_path).name == "free"
    # A cached "aware" entry is loaded, not recomputed: plant one and make synthesis fail.
    save_policy(result, aware_cache_path(town, driver, spec, tmp_path), town, driver, spec)
    monkeypatch.setattr(
        "trustroute.policies.resolve.synthesize", lambda *a, **k: pytest.fail("re-synthesized")
    )
    aware = resolve_policy("aware", town, driver, spec, tmp_path)
    assert aware.table.rows == result.policy.table.rows
    path = save_policy(result, tmp_path / "file.json", town, driver, spec)
    assert resolve_policy(str(path), town, driver, spec, tmp_path).table.rows == result.policy.table.rows
    with pytest.raises(InputError, match="not a policy file"):
        resolve_policy(str(tmp_path / "nope.json"), town, driver, spec, tmp_path)


def test_cli_synth_then_evaluate_and_mismatch_exit_code(capsys, tmp_path):
    out_path = tmp_path / "phi1.json"
    code, out, _ = run_cli(capsys, "synth", "specs/phi1.toml", "--horizon", "8", "--out", str(out_path),
                           "--json")
    assert code == 0
    payload = json.loads(out)
    assert {"lower", "upper", "gap", "seconds", "paths"} <= set(payload)
    assert payload["lower"] <= payload["upper"] and payload["paths"] == {
        "policy": str(out_path), "policy_arrays": str(out_path.with_suffix(".npz"))}
    assert out_path.is_file() and out_path.with_suffix(".npz").is_file()
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi1.toml", str(out_path), "--no-fallback",
                           "--max-junctions", "8", "--json")
    assert code == 0
    assert json.loads(out)["lower"] == pytest.approx(payload["lower"], abs=1e-12)
    code, out, err = run_cli(capsys, "evaluate", "specs/phi2.toml", str(out_path))
    assert code == 2 and out == ""
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1 and "another spec" in err
    code, _, err = run_cli(capsys, "synth", "specs/phi1.toml", "--tau", "0", "--out", str(out_path))
    assert code == 2 and "tau" in err


def test_cli_synth_clusters_on_writes_a_cluster_policy_that_evaluates_to_at_least_lower(capsys, tmp_path):
    out_path = tmp_path / "clusters.json"
    code, out, _ = run_cli(capsys, "synth", "specs/phi1.toml", "--horizon", "8", "--tau", "0.05",
                           "--clusters", "on", "--out", str(out_path))
    assert code == 0 and "a cluster policy:" in out and "box rows" in out
    assert json.loads(out_path.read_text())["box_rows"] > 0
    code, out, _ = run_cli(capsys, "synth", "specs/phi1.toml", "--horizon", "8", "--tau", "0.05",
                           "--clusters", "on", "--out", str(out_path), "--json")
    lower = json.loads(out)["lower"]
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi1.toml", str(out_path), "--no-fallback",
                           "--max-junctions", "8", "--json")
    assert code == 0 and json.loads(out)["lower"] >= lower - 1e-9
    code, _, err = run_cli(capsys, "synth", "specs/phi1.toml", "--clusters", "sometimes",
                           "--out", str(out_path))
    assert code == 2 and "--clusters" in err


def test_an_aware_policy_synthesized_into_a_named_cache_leaves_only_policy_files(
        town, driver, phi1_result, tmp_path, monkeypatch):
    """The entry's lock is kept in trustroute's own cache (core/cache.py entry_lock_path), not in a
    folder the user named for the policies."""
    spec, result = phi1_result
    monkeypatch.setattr("trustroute.policies.resolve.synthesize", lambda *a, **k: result)
    named = tmp_path / "policies"
    aware = resolve_policy("aware", town, driver, spec, named)
    assert aware.table.rows == result.policy.table.rows
    written = sorted(path.name for path in named.rglob("*") if path.is_file())
    assert written and not any(name.endswith(".lock") for name in written), written
