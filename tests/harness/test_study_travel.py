"""A study directory carries its inputs (harness/study/inputs.py): copied elsewhere, with the
originals and the policy cache gone, it is analysed, replayed and fitted from its own copies."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest

from tests.cli import run_cli
from tests.harness.helpers import run_study
from trustroute.core.packaged import SPECS
from trustroute.networks.town import DEFAULT_TOWN_PATH
from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH


def _travelled_study(root: Path, engine: str) -> Path:
    """Run a tiny study from temporary inputs, copy its directory, delete the originals."""
    inputs, cache = root / "inputs", root / "cache"
    inputs.mkdir(parents=True)
    for name in ("phi1", "phi2"):
        shutil.copy(SPECS.path(name), inputs / f"{name}.toml")
    shutil.copy(DEFAULT_TOWN_PATH, inputs / "mytown.json")
    shutil.copy(DEFAULT_DRIVER_MODEL_PATH, inputs / "mydriver.json")
    original = root / "original"
    run_study(inputs / "study.toml", f"""[study]
participants = 2
seed = 4
engine = "{engine}"
specs = ["phi1.toml", "phi2.toml"]
conditions = ["aware", "free"]
town = "mytown.json"
driver_model = "mydriver.json"
policy_cache = "{cache}"
horizon = 8
""", original)
    travelled = root / "elsewhere" / "study"
    shutil.copytree(original, travelled)
    for folder in (inputs, cache, original):   # the temporary inputs, the policy cache, the original
        shutil.rmtree(folder)
    return travelled


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    """No policy in the cache: the copy must not need one synthesized again."""
    cache = tmp_path / "fresh-cache"
    monkeypatch.setenv("XDG_CACHE_HOME", str(cache))
    monkeypatch.chdir(tmp_path)
    return cache


def _check_manifest(study: Path) -> dict:
    manifest = json.loads((study / "manifest.json").read_text())
    config = manifest["config"]
    paths = [*config["specs"], config["town"], config["driver_model"], config["policy_cache"],
             config["source_path"]]
    assert all(not Path(p).is_absolute() and p.startswith("inputs/") for p in paths), paths
    assert [Path(p).stem for p in config["specs"]] == ["phi1", "phi2"]   # labels kept
    files = manifest["inputs"]["files"]
    assert set(config["specs"]) | {config["town"], config["driver_model"]} <= set(files)
    for relative, entry in files.items():
        data = (study / relative).read_bytes()
        assert hashlib.sha256(data).hexdigest() == entry["sha256"]
        if not relative.startswith("inputs/policies/"):   # stored by content hash
            assert Path(relative).parent.name == entry["sha256"][:16]
    assert any(p.startswith("inputs/policies/aware-phi1-") for p in files)
    return manifest


def test_a_copied_model_study_is_analysed_replayed_and_fitted(tmp_path, fresh_cache, capsys):
    study = _travelled_study(tmp_path / "made", "model")
    _check_manifest(study)
    code, out, err = run_cli(capsys, "analyze", str(study), "--json")
    assert code == 0, err
    assert {(c["spec"], c["condition"]) for c in json.loads(out)["cells"]} == {
        (s, c) for s in ("phi1", "phi2") for c in ("aware", "free")}
    code, out, err = run_cli(capsys, "replay", str(study), "p00000-phi1-aware")
    assert code == 0, err
    assert "reproduces the log" in out and "no recording written: the study ran the model engine" in out
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi2-free", "--json")
    assert code == 0 and "model engine" in json.loads(out)["no_recording"]
    code, _, err = run_cli(capsys, "fit", str(study), "--out", str(tmp_path / "fitted.json"))
    assert code == 0, err
    assert not (fresh_cache / "trustroute" / "policies").exists()   # nothing synthesized again


def test_a_changed_or_missing_stored_input_is_refused(tmp_path, fresh_cache, capsys):
    study = _travelled_study(tmp_path / "made", "model")
    manifest = _check_manifest(study)
    town = study / manifest["config"]["town"]
    town.write_text(town.read_text().replace("  ", " "))
    code, out, err = run_cli(capsys, "analyze", str(study))
    assert code == 2 and err.count("\n") == 1 and "changed since it was run" in err
    code, _, err = run_cli(capsys, "replay", str(study), "p00000-phi1-aware")
    assert code == 2 and "changed since it was run" in err
    town.unlink()
    code, _, err = run_cli(capsys, "analyze", str(study))
    assert code == 2 and "stored input of the study is missing" in err


def test_a_copied_sumo_study_is_analysed_and_replayed_with_a_recording(tmp_path, fresh_cache, capsys):
    study = _travelled_study(tmp_path / "made", "sumo")
    _check_manifest(study)
    code, _, err = run_cli(capsys, "analyze", str(study), "--json")
    assert code == 0, err
    code, out, err = run_cli(capsys, "replay", str(study), "p00001-phi1-aware", "--json")
    assert code == 0, err
    payload = json.loads(out)
    assert payload["reproduced"] and payload["rrd_bytes"] > 0 and payload["no_recording"] is None
    assert Path(payload["rrd"]).is_relative_to(study)


def test_synth_without_out_writes_to_the_cache_and_says_where(tmp_path, fresh_cache, capsys):
    code, out, err = run_cli(capsys, "synth", "phi1", "--horizon", "3")
    assert code == 0, err
    written = Path(out.strip().splitlines()[-1].removeprefix("policy written to "))
    assert written.is_file() and written.with_suffix(".npz").is_file()
    assert written.is_relative_to(fresh_cache / "trustroute" / "policies" / "synth")
    assert list(tmp_path.glob("policy*")) == []   # nothing in the working directory


@pytest.mark.slow
def test_a_copied_robust_study_with_a_population_replays_without_synthesis(tmp_path, fresh_cache, capsys):

    made, cache = tmp_path / "made", tmp_path / "cache"
    made.mkdir()
    run_study(made / "r.toml", f"""[study]
participants = 2
seed = 2
engine = "model"
specs = ["phi1_strict"]
conditions = ["robust", "free"]
robust_population = "driver_population_three_types"
horizon = 4
policy_cache = "{cache}"
[drivers]
population = "driver_population_three_types"
""", made / "out")
    study = tmp_path / "elsewhere"
    shutil.copytree(made / "out", study)
    shutil.rmtree(made)
    shutil.rmtree(cache)
    config = json.loads((study / "manifest.json").read_text())["config"]
    assert all(config[key].startswith("inputs/") for key in ("robust_population", "driver_population"))
    assert any(p.name.startswith("robust-phi1_strict-") for p in (study / "inputs" / "policies").iterdir())
    code, _, err = run_cli(capsys, "analyze", str(study), "--json", "--no-report")
    assert code == 0, err
    code, out, err = run_cli(capsys, "replay", str(study), "p00000-phi1_strict-robust")
    assert code == 0 and "reproduces the log" in out, err
    assert not (fresh_cache / "trustroute" / "policies").exists()


def test_an_old_study_whose_town_is_gone_says_so_without_naming_an_option(tmp_path, fresh_cache, capsys):
    study = _travelled_study(tmp_path / "made", "model")
    manifest = json.loads((study / "manifest.json").read_text())
    del manifest["inputs"]   # as written before studies stored their inputs: absolute paths
    manifest["config"]["town"] = str(tmp_path / "gone" / "town.json")
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, out, err = run_cli(capsys, "analyze", str(study))
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "is gone" in err and "--town" not in err
