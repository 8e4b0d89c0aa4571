"""The synthesis entry point: specs without trust-state atoms give exactly `belief_synthesis.synthesize`'s
bounds and policy files (byte for byte); specs with them give joint policies usable everywhere."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from tests.cli import run_cli
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.aware_table import BoxRows
from trustroute.policies.routing.files import (
    ARRAY_NAMES,
    BOX_ARRAY_NAMES,
    PLAIN_KEYS,
    array_path,
    save_policy,
)
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.settings import SynthesisSettings


def _document(path) -> dict:
    document = json.loads(path.read_text())
    document.pop("seconds")        # wall time: the one entry two identical runs differ in
    return document


@pytest.mark.parametrize("name, horizon", [("phi1", 6), ("phi2_strict", 5)])
def test_without_trust_atoms_the_cli_writes_the_plain_synthesis_file_byte_for_byte(
        tmp_path, capsys, town, driver, pomdp, name, horizon):
    spec = load_spec(f"specs/{name}.toml", town)
    plain = synthesize(pomdp, spec, SynthesisSettings(horizon=horizon, time_limit=60))
    assert plain.gap <= 1e-3           # converged: the run is deterministic (no time cut)
    reference = save_policy(plain, tmp_path / "plain.json", town, driver, spec)
    code, out, _ = run_cli(capsys, "synth", f"specs/{name}.toml", "--horizon", str(horizon),
                           "--out", str(tmp_path / "cli.json"), "--json")
    assert code == 0
    payload = json.loads(out)
    assert (payload["lower"], payload["upper"]) == (plain.lower, plain.upper)
    assert array_path(tmp_path / "cli.json").read_bytes() == array_path(reference).read_bytes()
    document = _document(tmp_path / "cli.json")
    reference_document = _document(reference)
    reference_document["arrays"] = "cli.npz"
    assert document == reference_document
    # The plain format itself: exactly its keys and arrays, written as np.savez_compressed does.
    assert set(json.loads((tmp_path / "cli.json").read_text())) == set(PLAIN_KEYS)
    data = array_path(tmp_path / "cli.json").read_bytes()
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        assert sorted(archive.namelist()) == sorted(f"{a}.npy" for a in ARRAY_NAMES + BOX_ARRAY_NAMES)
    table = plain.policy.table
    assert table.boxes is None          # the search's policy: no box rows, empty box arrays
    boxes = BoxRows.empty(table.beliefs.shape[1])
    buffer = io.BytesIO()
    np.savez_compressed(buffer, t=table.t, x=table.x, q=table.q, projected=table.projected,
                        beliefs=table.beliefs, action=table.action, box_t=boxes.t, box_x=boxes.x,
                        box_q=boxes.q, box_lo=boxes.lo, box_hi=boxes.hi, box_value=boxes.value,
                        box_action=boxes.action)
    assert buffer.getvalue() == data


def test_a_trust_state_spec_synthesizes_and_its_file_evaluates_to_lower(tmp_path, capsys):
    policy = tmp_path / "trust.json"
    code, out, _ = run_cli(capsys, "synth", "specs/phi1_trust.toml", "--horizon", "8", "--out",
                           str(policy), "--json")
    assert code == 0
    synth = json.loads(out)
    assert synth["lower"] <= synth["upper"] and synth["gap"] <= 1e-3
    document = json.loads(policy.read_text())
    assert document["kind"] == "joint-belief" and document["guide_horizon"] == 8
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi1_trust.toml", str(policy), "--no-fallback",
                           "--max-junctions", "8", "--json")
    assert code == 0
    value = json.loads(out)
    assert value["lower"] == pytest.approx(synth["lower"], abs=1e-12)
    assert value["upper"] == pytest.approx(synth["lower"], abs=1e-12)
    # With the fallback past its horizon the policy still runs (it acts on the joint belief). The
    # joint evaluation merges equal nodes, but under one policy distinct observation histories
    # almost never reach bit-identical beliefs, so its cost still grows exponentially with the
    # cap: 14 junctions take a fraction of a second, 20 several seconds, the default 60 far longer.
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi1_trust.toml", str(policy), "--max-junctions",
                           "14", "--json")
    assert code == 0 and json.loads(out)["lower"] >= synth["lower"] - 1e-12
