"""Reading a study directory against its inputs: tables naming roads, incidents or specs the study's
inputs lack, trust outside its driver model's levels, and a manifest naming its inputs elsewhere
are each one InputError naming the file, the place in it and the fix."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest

from tests.cli import assert_one_line_error, run_cli
from tests.study_tables import set_values, study_copy
from trustroute.analysis.study.paper_comparison import is_paper_comparable
from trustroute.analysis.study_directory import load_study
from trustroute.core.dataset import EPISODES_FILE, MANIFEST_FILE, ROADS_FILE
from trustroute.core.errors import InputError
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.core.wording import counted
from trustroute.harness.study.inputs import MANIFEST_FIX, found_spec

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
    assert said.fix.startswith("put the spec the study was run with back at that path")
    # a relative path is never read where the command runs, even where a phi1.toml lies
    monkeypatch.chdir(tmp_path / "study")
    Path("phi1.toml").write_text(edited)
    with pytest.raises(InputError, match=r"config\.specs\[0\]"):
        load_study(_real_study_naming(tmp_path / "relative", "phi1.toml", recorded))
    # the packaged spec's own SHA-256 recorded: it is the study's spec
    manifest, episodes, _ = load_study(_real_study_naming(tmp_path / "same", str(gone), shipped))
    assert set(episodes["spec"]) == {"phi1", "phi2"}


REIMPORT = "or import it again (`trustroute import carla-logs SOURCE --out DIR`), which records its specs'"


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def test_a_spec_edited_at_its_recorded_path_since_the_study_ran_is_not_read(tmp_path):
    """The study ran the lab's own phi1.toml, whose SHA-256 the manifest records, and the file was
    edited since at the same path: reading it would analyse another spec, so one line names the
    manifest, the key, the SHA-256 that differs and the fix. The file as the study ran it is read;
    and where the manifest records the packaged file's SHA-256, the packaged spec, provably the one
    the study ran, stands in for the edited file."""
    lab = tmp_path / "lab" / "phi1.toml"
    lab.parent.mkdir()
    ran = (PACKAGED_SPECS / "phi1.toml").read_text() + "# the lab's own edit\n"
    lab.write_text(ran)
    shipped = json.loads((REAL_STUDY / MANIFEST_FILE).read_text())["config"]["spec_sha256"]
    study = _real_study_naming(tmp_path, str(lab), [_sha256(ran), shipped[1]])
    assert load_study(study)[0]["config"]["specs"][0] == str(lab)   # the same file: read
    lab.write_text(ran + "# edited after the study\n")
    with pytest.raises(InputError) as info:
        load_study(study)
    said = info.value
    assert (said.source, said.place) == (str(study / MANIFEST_FILE), "config.specs[0]")
    assert said.problem.startswith(f"the study's spec {lab} changed since the study was run (its SHA-256 "
                                   "differs from config.spec_sha256[0]), and the packaged phi1.toml is not "
                                   "provably the spec the study ran")
    assert said.fix.startswith("put the spec the study was run with back at that path")
    _, episodes, _ = load_study(_real_study_naming(tmp_path / "packaged", str(lab), shipped))
    assert set(episodes["spec"]) == {"phi1", "phi2"}


@pytest.mark.parametrize("recorded", [{"phi1.toml": "x"}, 5, True, "be0ef16eef1fe63f0570b5cc5087d542",
                                      ["not a digest", None], [None, "6F43B9CB" * 8],
                                      [None], [None, None, None]])
def test_a_spec_sha256_that_is_no_list_of_digests_is_one_line(recorded, tmp_path, capsys):
    """`config.spec_sha256` of another type, with an entry that is no SHA-256, or not one entry per
    spec (a shorter list would leave a spec unverified), is refused before any spec is looked for:
    one line naming the manifest and the key, exit 2 (never a traceback, nor a string read a
    character at a time); an imported study's fix says it can be imported again."""
    study = _real_study_naming(tmp_path, "policies/specs/phi1.toml", [])
    manifest = json.loads((study / MANIFEST_FILE).read_text())
    manifest["config"]["spec_sha256"] = recorded
    (study / MANIFEST_FILE).write_text(json.dumps(manifest))
    code, out, err = run_cli(capsys, "analyze", str(study), "--json")
    wrong = (json.dumps(recorded)[:20] if not isinstance(recorded, list) else
             f"it has {counted(len(recorded), 'entry', 'entries')} for 2 specs" if len(recorded) != 2 else
             "its entry [")
    assert_one_line_error(code, err, f"{study / MANIFEST_FILE}: config.spec_sha256: not a list of the specs' "
                          "SHA-256", wrong, MANIFEST_FIX, REIMPORT)
    assert out == ""


@pytest.mark.parametrize("entry", [None, 7, "phi1\u0000.toml"])
def test_a_spec_entry_that_is_no_path_is_one_line(entry, tmp_path, capsys):
    """A `config.specs` entry that is no path (null, a number, a NUL in it) is one line naming the
    manifest and its place, exit 2, not a traceback."""
    study = _real_study_naming(tmp_path, entry, None)
    code, out, err = run_cli(capsys, "analyze", str(study), "--json")
    assert_one_line_error(code, err, f"{study / MANIFEST_FILE}: config.specs[0]: not a spec's path")
    assert out == ""


def test_a_spec_recorded_on_windows_is_matched_by_its_file_name(tmp_path):
    """A study imported on Windows records `C:\\...\\phi1.toml`: an absolute path gone here, whose
    file name is phi1.toml, so the packaged phi1.toml with the recorded SHA-256 stands in; without
    a SHA-256 recorded the path is said gone, not relative."""
    windows = "C:\\Users\\lab\\trustroute\\policies\\specs\\phi1.toml"
    shipped = json.loads((REAL_STUDY / MANIFEST_FILE).read_text())["config"]["spec_sha256"]
    manifest, episodes, _ = load_study(_real_study_naming(tmp_path / "hashed", windows, shipped))
    assert set(episodes["spec"]) == {"phi1", "phi2"}
    assert is_paper_comparable(manifest, episodes)[0]   # its phi1 is the paper's, by its file name
    with pytest.raises(InputError) as info:
        load_study(_real_study_naming(tmp_path / "unhashed", windows, None))
    assert info.value.problem.startswith(f"the study's spec {windows} is gone")


def test_a_backslash_in_a_file_name_here_is_part_of_the_name(tmp_path):
    """On this system a backslash may be part of a file name: `a\\phi1.toml` is not read as a
    Windows path to phi1.toml, so the packaged phi1.toml does not stand in for it by name; the file
    itself, with the recorded SHA-256, is the one found."""
    spec = tmp_path / "a\\phi1.toml"
    spec.write_bytes((PACKAGED_SPECS / "phi1.toml").read_bytes())
    config = {"specs": [str(spec)], "spec_sha256": [hashlib.sha256(spec.read_bytes()).hexdigest()]}
    assert found_spec(config, 0) == spec


@pytest.mark.parametrize("specs", ["phi1.toml", {"phi1": "phi1.toml"}])
def test_specs_that_are_no_list_are_one_line(specs, tmp_path, capsys):
    """`config.specs` that is no list is one line naming `config.specs`, exit 2 (never read a
    character or a key at a time)."""
    study = _real_study_naming(tmp_path, "policies/specs/phi1.toml", None)
    manifest = json.loads((study / MANIFEST_FILE).read_text())
    manifest["config"]["specs"] = specs
    (study / MANIFEST_FILE).write_text(json.dumps(manifest))
    code, out, err = run_cli(capsys, "analyze", str(study), "--json")
    assert_one_line_error(code, err, f"{study / MANIFEST_FILE}: config.specs: not a list of spec paths")
    assert out == ""


def test_the_packaged_copy_with_the_recorded_sha256_is_the_one_found_and_exported(tmp_path, capsys):
    """A study imported by another install names that install's spec, byte for byte the packaged
    one (the recorded SHA-256): the packaged copy is the one found, so the export ships it rather
    than leave the spec out of the package."""
    other_install = tmp_path / "other" / "policies" / "specs" / "phi1.toml"
    other_install.parent.mkdir(parents=True)
    other_install.write_bytes((PACKAGED_SPECS / "phi1.toml").read_bytes())
    shipped = json.loads((REAL_STUDY / MANIFEST_FILE).read_text())["config"]["spec_sha256"]
    study = _real_study_naming(tmp_path, str(other_install), shipped)
    config = json.loads((study / MANIFEST_FILE).read_text())["config"]
    assert found_spec(config, 0) == PACKAGED_SPECS / "phi1.toml"
    package = tmp_path / "package"
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(package))
    assert code == 0, err
    readme = (package / "README.md").read_text()
    assert "config.specs[0]" not in readme   # nothing left out
    assert any(path.name == "phi1.toml" for path in (package / "inputs").rglob("*.toml"))


def test_a_relative_spec_path_is_said_to_be_no_stored_input_nor_absolute_not_gone(model_study, tmp_path):
    """A relative spec path is never read, so it is not "gone": it is neither a stored input nor an
    absolute path, as a town's is said to be; an imported study recorded before the import recorded its
    specs' SHA-256 is imported again, a simulated study's manifest restored."""
    from trustroute.harness.study.inputs import config_sha256

    imported = _real_study_naming(tmp_path, "policies/specs/phi1.toml", None)
    with pytest.raises(InputError) as info:
        load_study(imported)
    said = info.value
    assert said.place == "config.specs[0]" and "gone" not in said.problem
    assert said.problem.startswith("the study's spec 'policies/specs/phi1.toml' is neither one of its stored "
                                   "inputs (inputs/...) nor an absolute path, and the packaged phi1.toml is "
                                   "not provably the spec the study ran (the manifest records no SHA-256")
    assert REIMPORT in said.fix
    simulated = study_copy(model_study, tmp_path / "simulated")
    manifest = json.loads((simulated / MANIFEST_FILE).read_text())
    manifest["config"]["specs"][0] = "phi1.toml"
    manifest["inputs"]["config_sha256"] = config_sha256(manifest["config"])
    (simulated / MANIFEST_FILE).write_text(json.dumps(manifest))
    with pytest.raises(InputError) as info:
        load_study(simulated)
    assert info.value.problem.startswith("the study's spec 'phi1.toml' is neither one of its stored inputs")
    assert info.value.fix == MANIFEST_FIX and "gone" not in info.value.problem


def test_the_inputs_check_words_a_study_directory_as_one_whatever_hashes_it_is_given(model_study, tmp_path):
    """`verify_inputs` names the manifest and gives the fix by what the folder is (`manifest_wording`,
    the rule every message on a manifest follows), not by whether its caller passes hashes already
    verified: a study directory's missing input and edited config are worded as a study directory's
    (manifest.json, restore it), with its files hashed or their hashes given alike."""
    from trustroute.core.package import sha256_of
    from trustroute.harness.study.inputs import verify_inputs

    study = study_copy(model_study, tmp_path / "study")
    manifest = json.loads((study / MANIFEST_FILE).read_text())
    recorded = manifest["inputs"]["files"]
    hashes = {relative: sha256_of(study / relative) for relative in recorded}
    config = manifest["config"]
    edited = {**manifest, "config": {**config, "participants": config["participants"] + 1}}
    for checked in (None, hashes):
        with pytest.raises(InputError) as info:
            verify_inputs(edited, study, checked)
        assert (info.value.source, info.value.place) == (str(study / MANIFEST_FILE), "config")
        assert info.value.fix == MANIFEST_FIX
    gone = sorted(recorded)[0]
    (study / gone).unlink()
    for checked in (None, {k: v for k, v in hashes.items() if k != gone}):
        with pytest.raises(InputError) as info:
            verify_inputs(manifest, study, checked)
        assert (info.value.source, info.value.place) == (str(study), gone)
        assert "a stored input of the study is missing" in info.value.problem
        assert "copy the whole study directory" in info.value.fix
