"""Reading a study directory against its inputs: tables naming roads, incidents or specs the study's
inputs lack, trust outside its driver model's levels, and a manifest naming its inputs elsewhere
are each one InputError naming the file, the place in it and the fix."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.study_tables import set_values, study_copy
from trustroute.analysis.study_directory import load_study
from trustroute.core.dataset import EPISODES_FILE, MANIFEST_FILE, ROADS_FILE
from trustroute.core.errors import InputError

# (table, edit, column, what the message says)
UNKNOWN_NAMES = {
    "road": (ROADS_FILE, set_values("directed_road", "ZZ-YY"), "directed_road", "'ZZ-YY' is not a road of"),
    "incident": (ROADS_FILE, set_values("incident", "meteor", [3]), "incident",
                 "'meteor' is not an incident type of the study's driver model (obstacle"),
    "spec": (EPISODES_FILE, set_values("spec", "phi9", [5]), "spec",
             "'phi9' is not one of the study's specs"),
    "reported_trust": (ROADS_FILE, set_values("reported_trust", 99, [3]), "reported_trust",
                       "99 is not a trust level of the study's driver model (1, 2, 3, 4, 5, 6, 7)"),
    "final_trust": (EPISODES_FILE, set_values("final_trust", 0, [5]), "final_trust",
                    "0 is not a trust level"),
}


@pytest.mark.parametrize("case", sorted(UNKNOWN_NAMES))
def test_a_value_the_study_s_inputs_lack_names_the_table_column_and_row(case, model_study, tmp_path):
    file_name, edit, column, problem = UNKNOWN_NAMES[case]
    study = study_copy(model_study, tmp_path / "study", file_name, edit)
    with pytest.raises(InputError) as info:
        load_study(study)
    row = {"road": 0, "incident": 3, "spec": 5, "reported_trust": 3, "final_trust": 5}[case]
    assert (info.value.source, info.value.place) == (str(study / file_name), f"{column}, row {row}")
    assert problem in info.value.problem and "rebuild" in info.value.fix


def _with_town(model_study: Path, tmp_path: Path, town: str) -> Path:
    """A copy of the study whose manifest names `town`, as if it had been run so (its config's
    SHA-256 recorded again, so the manifest is not taken for an edited one)."""
    from trustroute.harness.study.inputs import config_sha256

    study = study_copy(model_study, tmp_path / "study")
    manifest = json.loads((study / MANIFEST_FILE).read_text())
    manifest["config"]["town"] = town
    manifest["inputs"]["config_sha256"] = config_sha256(manifest["config"])
    (study / MANIFEST_FILE).write_text(json.dumps(manifest))
    return study


@pytest.mark.parametrize("town", ["../../../../etc/passwd", "inputs/../../../../etc/passwd", "/etc/passwd",
                                  "town01_carla.json"])
def test_a_town_the_manifest_names_outside_the_study_is_refused_naming_the_key(town, model_study, tmp_path,
                                                                                monkeypatch):
    """Never read relative to where the command runs, never out of the stored inputs; a file that is
    no town is named by the manifest's key, not only by its own path."""
    monkeypatch.chdir(tmp_path)
    # a file of that name where the command runs, not the study's town
    shutil.copyfile(model_study / MANIFEST_FILE, tmp_path / "town01_carla.json")
    study = _with_town(model_study, tmp_path, town)
    with pytest.raises(InputError) as info:
        load_study(study)
    assert (info.value.source, info.value.place) == (str(study / MANIFEST_FILE), "config.town")
    assert town in info.value.problem


def test_a_town_file_of_the_user_s_own_by_absolute_path_is_still_read(model_study, tmp_path):
    recorded = json.loads((model_study / MANIFEST_FILE).read_text())["config"]["town"]
    own = tmp_path / "my_town.json"
    shutil.copyfile(model_study / recorded, own)
    manifest, _, roads = load_study(_with_town(model_study, tmp_path, str(own)))
    assert manifest["config"]["town"] == str(own) and len(roads)


REAL_STUDY = Path(__file__).resolve().parents[2] / "analysis" / "data" / "real_study" / "study"


def _real_study_naming(tmp_path: Path, spec: str, recorded: list[str] | None) -> Path:
    """A copy of the imported real study (no stored inputs) whose config names `spec` as its first
    spec and records `recorded` as its specs' SHA-256 (None: records none)."""
    study = Path(shutil.copytree(REAL_STUDY, tmp_path / "study"))
    manifest = json.loads((study / MANIFEST_FILE).read_text())
    manifest["config"]["specs"][0] = spec
    if recorded is None:
        del manifest["config"]["spec_sha256"]
    else:
        manifest["config"]["spec_sha256"] = recorded
    (study / MANIFEST_FILE).write_text(json.dumps(manifest))
    return study


@pytest.mark.parametrize("records", ["none", "the edited file's"])
def test_a_gone_spec_is_not_read_as_the_packaged_one_of_its_name_unless_it_is_that_one(records, tmp_path,
                                                                                        monkeypatch):
    """The study was run with the lab's own, edited phi1.toml, since removed: the packaged phi1.toml
    shares only its name, so reading it would analyse another spec. One line naming the manifest,
    the key and the fix, whether the manifest records no SHA-256 of the spec or the edited file's;
    nor is a relative path read from where the command runs. With the packaged file's SHA-256 the
    packaged spec is the one the study ran, and stands in."""
    import hashlib

    from trustroute.core.packaged import PACKAGED_SPECS

    packaged = PACKAGED_SPECS / "phi1.toml"
    edited = packaged.read_text() + "# the lab's own edit\n"
    gone = tmp_path / "lab" / "phi1.toml"
    shipped = json.loads((REAL_STUDY / MANIFEST_FILE).read_text())["config"]["spec_sha256"]
    recorded = None if records == "none" else [hashlib.sha256(edited.encode()).hexdigest(), shipped[1]]
    study = _real_study_naming(tmp_path, str(gone), recorded)
    with pytest.raises(InputError) as info:
        load_study(study)
    said = info.value
    assert (said.source, said.place) == (str(study / MANIFEST_FILE), "config.specs[0]")
    assert f"the study's spec {gone} is gone" in said.problem and "not provably" in said.problem
    assert said.fix.startswith(f"restore {gone}")
    # a relative path is never read where the command runs, even where a phi1.toml lies
    monkeypatch.chdir(tmp_path / "study")
    Path("phi1.toml").write_text(edited)
    with pytest.raises(InputError, match=r"config\.specs\[0\]"):
        load_study(_real_study_naming(tmp_path / "relative", "phi1.toml", recorded))
    # the packaged spec's own SHA-256 recorded: it is the study's spec
    manifest, episodes, _ = load_study(_real_study_naming(tmp_path / "same", str(gone), shipped))
    assert set(episodes["spec"]) == {"phi1", "phi2"}
