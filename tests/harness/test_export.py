"""`trustroute export` of a simulated study: every participant gets a distinct pseudonym, however
many the study has (a config allows up to 100,000); the rows follow the pseudonyms, not the order of
enrolment; the README reports the participant flow."""

from __future__ import annotations

import getpass
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import trustroute
from tests.cli import assert_one_line_error, run_cli
from tests.export_checks import (
    assert_no_wall_clock,
    assert_nothing_identifying,
    assert_rows_in_code_order,
    assert_task_inputs,
    package_key,
)
from tests.lock_holder import another_process_holds
from trustroute.core.package import sha256_of
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.export import pseudonyms, read_export_keys


@pytest.mark.parametrize(("participants", "low", "high"), [(2, 100, 999), (900, 100, 999),
                                                           (901, 1000, 9999), (9001, 10000, 99999)])
def test_pseudonyms_are_distinct_codes_of_one_length(participants, low, high):
    key = pseudonyms(list(range(participants)), np.random.default_rng(0))
    codes = list(key.values())
    assert sorted(key) == list(range(participants)) and len(set(codes)) == participants
    assert low <= min(codes) and max(codes) <= high


@pytest.mark.slow
def test_a_study_of_more_than_900_participants_exports(tmp_path, capsys):
    study = trustroute.run_study({"study": {"participants": 901, "seed": 1, "engine": "model",
                                            "specs": ["phi1"], "conditions": ["free"]}},
                                 out=tmp_path / "study").study_dir
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert code == 0, err
    episodes = pq.read_table(tmp_path / "package" / "tables" / "episodes.parquet").to_pandas()
    assert episodes["participant"].nunique() == 901
    assert episodes["episode_id"].str.fullmatch(r"p\d{5}-phi1-free").all()


def test_a_package_path_that_is_a_file_is_one_line_naming_out(model_study, capsys, tmp_path):
    taken = tmp_path / "package.zip"
    taken.write_text("a file")
    code, out, err = run_cli(capsys, "export", str(model_study), "--out", str(taken))
    assert code == 2 and out == ""
    assert err == (f"error: {taken}: --out: the package directory exists and is not a directory "
                   "(fix: pass a directory to --out)\n")


def test_a_package_says_nothing_of_the_order_of_enrolment(model_study, tmp_path, capsys):
    study = shutil.copytree(model_study, tmp_path / "study")
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"), "--seed", "2")
    assert code == 0, err
    key = package_key(study, tmp_path / "package")
    codes = [key[p] for p in range(12)]
    assert codes != sorted(codes)   # enrolment order and code order differ: the check below means something
    assert_rows_in_code_order(tmp_path / "package", study)
    assert_no_wall_clock(tmp_path / "package")
    readme = (tmp_path / "package" / "README.md").read_text()
    assert "Participants: 12 planned, 12 with data in this package." in readme
    # the codebook describes the codes the tables hold (100-999 for 12 participants), not the study's numbers
    book = {entry["column"]: entry
            for entry in json.loads((tmp_path / "package" / "codebook.json").read_text())["episodes"]}
    assert "100-999" in book["participant"]["allowed"] and all(100 <= c <= 999 for c in codes)
    assert "random code (three digits" in readme and "code 114 is `p00114`" in readme
    assert book["episode_id"]["allowed"].startswith("p<participant code, 5 digits")
    ids = pq.read_table(tmp_path / "package" / "tables" / "episodes.parquet").column("episode_id").to_pylist()
    matches = [re.fullmatch(r"p00([1-9]\d\d)-phi[12]-(aware|free)", episode) for episode in ids]
    assert {int(match.group(1)) for match in matches if match} == set(codes) and all(matches)
    assert "withdrawn" not in readme   # a simulated study has no withdrawals to report
    # nor texts shown to anyone: the README lists no `texts/` folder the package does not have
    assert not (tmp_path / "package" / "texts").exists() and "`texts/`" not in readme
    # nor anyone to hide: it keeps the seeds that reproduce it
    study_seed = json.loads((study / "manifest.json").read_text())["config"]["seed"]
    assert json.loads((tmp_path / "package" / "study_config.json").read_text())["seed"] == study_seed
    seeds = [pq.read_table(folder / "episodes.parquet").column("seed").to_pylist()
             for folder in (tmp_path / "package" / "tables", study)]
    assert sorted(seeds[0]) == sorted(seeds[1])


def test_each_package_keeps_its_key_and_a_key_is_never_dropped(model_study, tmp_path, capsys):
    """A lab shares one package on OSF and another (another --seed) with a journal: the study's key
    file keeps the key of each, so that a withdrawal can name both. Emptying the OSF package's
    folder and exporting there again with another key keeps the first key (that package may have
    been shared, moved or copied); exporting there again with the same key replaces its entry."""
    study = shutil.copytree(model_study, tmp_path / "study")
    osf, journal = tmp_path / "osf", tmp_path / "journal"
    first: dict[int, int] = {}
    for package, seed in ((osf, "2"), (journal, "3"), (osf, "4"), (osf, "4")):
        shutil.rmtree(package, ignore_errors=True)
        code, _, err = run_cli(capsys, "export", str(study), "--out", str(package), "--seed", seed)
        assert code == 0, err
        first = first or package_key(study, osf)   # the key of the package first shared on OSF
    entries = read_export_keys(study)
    assert [entry["package"] for entry in entries] == [str(p.resolve()) for p in (osf, journal, osf)]
    assert all(re.fullmatch(r"\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}Z", entry["written_utc"])
               for entry in entries)
    seed_2 = {int(p): code for p, code in entries[0]["pseudonyms"].items()}
    assert seed_2 == first != package_key(study, osf)   # the first OSF package's key is kept
    for package in (osf, journal):   # the newest entry of each path is the key of its package
        assert_rows_in_code_order(package, study)
    assert package_key(study, osf) != package_key(study, journal)
    assert not list(osf.rglob("export-key*"))   # the keys stay in the study


def test_an_export_is_refused_while_another_process_holds_the_study(model_study, tmp_path, capsys):
    """A run writing the study (a live server, a study resumed) holds its lock: an export then is
    one line naming that process, with no package and no key written; once it has let go, the
    export goes ahead. A folder that is no study is refused before any lock file is made in it."""
    study = shutil.copytree(model_study, tmp_path / "study")
    with another_process_holds(study) as pid:
        code, out, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
        assert_one_line_error(code, err, str(study), f"in use by pid {pid}", "then export again")
        assert out == "" and not (tmp_path / "package").exists()
        assert not (study / "export-key.json").exists()
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert code == 0, err
    logs = tmp_path / "logs"
    logs.mkdir()
    code, _, err = run_cli(capsys, "export", str(logs), "--out", str(tmp_path / "other"))
    assert_one_line_error(code, err, str(logs), "no manifest")
    assert list(logs.iterdir()) == []


def test_a_key_file_of_the_single_package_form_is_read_and_kept(model_study, tmp_path, capsys):
    """A key file written with one package's key ({"package", "pseudonyms"}) is that package's entry:
    a later export adds its own beside it. A key file that cannot be read refuses the export before
    anything is written, since writing it again would lose the keys of the packages it holds."""
    study = shutil.copytree(model_study, tmp_path / "study")
    shared = str(tmp_path / "shared-before")
    single = {"pseudonyms": {"0": 417, "1": 902}, "package": shared}
    (study / "export-key.json").write_text(json.dumps(single))
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert code == 0, err
    first, second = read_export_keys(study)
    assert first == {**single, "written_utc": None}
    assert second["package"] == str((tmp_path / "package").resolve())
    (study / "export-key.json").write_text(json.dumps({"packages": [first, {"package": 3}]}))
    code, out, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "again"))
    assert_one_line_error(code, err, str(study / "export-key.json"), "packages[1].package",
                          "restore it from a backup")
    assert out == "" and not (tmp_path / "again").exists()


def test_a_time_that_is_not_a_utc_date_time_is_one_line_and_no_package(model_study, tmp_path, capsys):
    from trustroute.core.dataset import ATTEMPTS_SCHEMA, write_table

    study = shutil.copytree(model_study, tmp_path / "study")
    row = {"participant": 0, "episode_id": "p00000-phi1-free", "warm_up": False, "planned_position": 0,
           "attempt": 1, "sequence": 1, "run_position": 0, "started_utc": "2026-01-05T09:00:00Z",
           "ended_utc": "at nine", "outcome": "done", "reason": None}
    write_table(pa.Table.from_pylist([row], ATTEMPTS_SCHEMA), study / "attempts.parquet")
    code, out, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert_one_line_error(code, err, str(study / "attempts.parquet"), "ended_utc, row 0",
                          "not an ISO 8601 UTC date-time: 'at nine'")
    assert out == "" and not (tmp_path / "package" / "tables").exists()


def test_an_imported_study_exports_without_the_drivers_numbers(tmp_path, capsys):
    """The real CARLA study's episode ids (`d24-t1-aware`) carry the authors' driver numbers: the
    package renames them to the pseudonym's `p<code>-<spec>-<condition>` in every table, sorts every
    table by code, counts the participants without a plan, and names the logs' authors and licence."""
    study = shutil.copytree("analysis/data/real_study/study", tmp_path / "study")
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert code == 0, err
    key = package_key(study, tmp_path / "package")
    tables = tmp_path / "package" / "tables"
    originals = pq.read_table(study / "episodes.parquet").to_pandas()
    exported = pq.read_table(tables / "episodes.parquet").to_pandas()
    expected = {f"p{key[p]:05d}-{s}-{c}" for p, s, c in
                originals[["participant", "spec", "condition"]].itertuples(index=False)}
    assert set(exported["episode_id"]) == expected and len(exported) == len(originals)
    assert (exported["episode_id"].str[1:6].astype(int) == exported["participant"]).all()
    for name in ("roads", "kinematics"):
        ids = pq.read_table(tables / f"{name}.parquet").column("episode_id").to_pylist()
        assert set(ids) <= expected, name
        codes = [int(e[1:6]) for e in ids]
        assert codes == sorted(codes), name
    # the codebook describes the values the import writes where no simulator ran (-1)
    book = {(table, e["column"]): e["allowed"]
            for table, entries in json.loads((tmp_path / "package" / "codebook.json").read_text()).items()
            for e in entries}
    for table, column in (("episodes", "seed"), ("roads", "dfa_state")):
        values = set(pq.read_table(tables / f"{table}.parquet").column(column).to_pylist())
        assert values == {-1} and "; -1: " in book[table, column], (column, book[table, column])
    readme = (tmp_path / "package" / "README.md").read_text()
    assert "Participants: 21 with data in this package." in readme
    assert "Copyright (c) 2025 Shuyang Dong" in readme and "MIT licence" in readme


def test_a_package_holds_the_inputs_that_define_the_task(model_study, tmp_path, capsys):
    """The specs, the town, the driver model, the config file and the policies the aware condition
    drove are in the package where its study_config.json names them, with their hashes; the config
    file's policy cache, an absolute path of the lab's disk, names the package's copy instead."""
    study = shutil.copytree(model_study, tmp_path / "study")
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert code == 0, err
    package = tmp_path / "package"
    assert_task_inputs(package)
    config = json.loads((package / "study_config.json").read_text())
    assert [Path(p).name for p in config["specs"]] == ["phi1.toml", "phi2.toml"]
    policies = sorted(p.name for p in (package / config["policy_cache"]).iterdir())
    assert [p for p in policies if p.startswith("aware-")] == policies and len(policies) == 4
    written = (package / config["source_path"]).read_text()
    assert 'policy_cache = "inputs/policies"' in written
    cache = str(load_study_config(model_study.parent / "study.toml").policy_cache)   # its policies
    assert_nothing_identifying(package, [str(tmp_path), str(model_study), cache, str(Path.cwd()),
                                         str(Path(trustroute.__file__).parent)])


def test_an_input_is_read_before_it_enters_the_package(tmp_path, capsys):
    """An absolute path in a copied file becomes the package's copy it names, or a mark; a file
    naming the account that exports is left out, and so is one holding a token-shaped string, and
    the README says why; a symbolic link in inputs/ to a file outside the study is not followed."""
    from trustroute.harness.live.auth import new_token
    from trustroute.harness.study.export_inputs import PATH_LEFT_OUT
    from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH

    lab = tmp_path / "lab"
    lab.mkdir()
    model = json.loads(Path(DEFAULT_DRIVER_MODEL_PATH).read_text())
    spec = lab / "route.toml"
    spec.write_text(Path(trustroute.__file__).parent.joinpath("core/specs/phi1.toml").read_text()
                    + f"# link: https://lab.example/s?t={new_token()}\n")
    model["source"] = f"fitted by `trustroute fit {lab}/pilot` beside {spec}"
    (lab / "driver.json").write_text(json.dumps(model))
    (lab / "study.toml").write_text(f"""# run by {getpass.getuser()}
[study]
participants = 2
seed = 1
engine = "model"
specs = ["route.toml", "phi2"]
conditions = ["free"]
driver_model = "driver.json"
""")
    study = trustroute.run_study(lab / "study.toml", out=tmp_path / "study").study_dir
    config = json.loads((study / "manifest.json").read_text())["config"]
    town = study / config["town"]
    outside = tmp_path / "elsewhere.json"
    outside.write_bytes(town.read_bytes())   # the same bytes: the study's hash check passes
    town.unlink()
    town.symlink_to(outside)
    package = tmp_path / "package"
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(package))
    assert code == 0, err
    readme = (package / "README.md").read_text()
    model_copy = (package / config["driver_model"]).read_text()
    assert f"beside {config['specs'][0]}" in model_copy and PATH_LEFT_OUT in model_copy
    for left_out, why in ((config["specs"][0], "a string of the form of a participant's token"),
                          (config["source_path"], "the user name of the account that runs the export"),
                          (config["town"], "a symbolic link leading out of inputs/")):
        assert not (package / left_out).exists()
        assert re.search(rf"`{left_out}`: left out, since [^\n]*{why}", readme), left_out
    assert (package / config["specs"][1]).is_file()
    assert_nothing_identifying(package, [str(tmp_path), getpass.getuser()])


def test_an_imported_study_packages_the_task_its_analysis_used(tmp_path, capsys):
    """The real CARLA study stores no inputs: its package holds the specs, the town and the driver
    model its analysis loads (the packaged phi1 and phi2, the default town and driver model), byte for
    byte as the installed package ships them, where its study_config.json names them inside the
    package, with their hashes and roles, and no path of the lab's disk or of the installation."""
    from trustroute.analysis.study_directory import load_study, study_inputs
    from trustroute.core.packaged import PACKAGED_SPECS
    from trustroute.networks.town import DEFAULT_TOWN_PATH, load_town
    from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH, load_driver_model
    from trustroute.policies.logic.spec import load_spec

    study = shutil.copytree("analysis/data/real_study/study", tmp_path / "study")
    package = tmp_path / "package"
    code, out, err = run_cli(capsys, "export", str(study), "--out", str(package), "--json")
    assert code == 0, err
    assert_task_inputs(package, ("specs", "town", "driver_model"))
    config = json.loads((package / "study_config.json").read_text())
    named = {"town": config["town"], "driver_model": config["driver_model"],
             **{Path(p).stem: p for p in config["specs"]}}
    assert all((package / p).resolve().is_relative_to(package.resolve()) for p in named.values()), named
    shipped = {"town": DEFAULT_TOWN_PATH, "driver_model": DEFAULT_DRIVER_MODEL_PATH,
               "phi1": PACKAGED_SPECS / "phi1.toml", "phi2": PACKAGED_SPECS / "phi2.toml"}
    assert {k: (package / p).read_bytes() for k, p in named.items()} == {
        k: p.read_bytes() for k, p in shipped.items()}
    index = json.loads(out)
    assert sorted(index["inputs"]) == sorted(named.values()) and index["inputs_left_out"] == {}
    # the very task the analysis reads from the study directory
    town, driver, specs = study_inputs(load_study(study)[0], study)
    copied = load_town(package / named["town"])
    assert (copied.content_hash, load_driver_model(package / named["driver_model"]).content_hash) == (
        town.content_hash, driver.content_hash)
    assert {name: load_spec(package / named[name], copied).content_hash for name in specs} == {
        name: spec.content_hash for name, spec in specs.items()}
    readme = (package / "README.md").read_text()
    spec = "spec (formula, start road, atoms)"
    for what, role in (("town", "town"), ("driver_model", "driver model"), ("phi1", spec), ("phi2", spec)):
        assert f"  - `{named[what]}`: {role}.\n" in readme, what
    installed = [str(Path(trustroute.__file__).parent), *(str(p.parent) for p in shipped.values())]
    assert_nothing_identifying(package, [str(tmp_path), str(Path.cwd()), *installed])


def test_an_imported_study_names_no_path_of_the_lab_in_its_package(tmp_path, capsys):
    """The import names its specs by their absolute paths where it ran (the packaged specs), and a
    path gone since is read as the packaged spec of its name, as the analysis reads it: the package
    holds both, and neither its config nor any file names a path of the lab's disk."""
    from trustroute.core.packaged import PACKAGED_SPECS

    study = shutil.copytree("analysis/data/real_study/study", tmp_path / "study")
    manifest = json.loads((study / "manifest.json").read_text())
    manifest["config"]["specs"] = [str(PACKAGED_SPECS / "phi1.toml"), str(tmp_path / "gone" / "phi2.toml")]
    (study / "manifest.json").write_text(json.dumps(manifest))
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert code == 0, err
    config = json.loads((tmp_path / "package" / "study_config.json").read_text())
    assert [(tmp_path / "package" / p).read_bytes() for p in config["specs"]] == [
        (PACKAGED_SPECS / name).read_bytes() for name in ("phi1.toml", "phi2.toml")]
    assert_task_inputs(tmp_path / "package", ("specs", "town", "driver_model"))
    assert_nothing_identifying(tmp_path / "package", [str(tmp_path), str(PACKAGED_SPECS)])


def test_a_task_file_the_package_does_not_ship_is_not_read(tmp_path, capsys):
    """A study that stored no inputs and names a spec of the lab's disk (which its analysis reads):
    the export reads nothing outside the study directory and the installed package, so that spec is
    left out, the README says so under its config place, and study_config.json names no path."""
    from trustroute.core.packaged import PACKAGED_SPECS
    from trustroute.harness.study.export_inputs import PATH_LEFT_OUT

    lab = tmp_path / "lab"
    lab.mkdir()
    (lab / "phi1.toml").write_text((PACKAGED_SPECS / "phi1.toml").read_text() + "# the lab's own copy\n")
    study = shutil.copytree("analysis/data/real_study/study", tmp_path / "study")
    manifest = json.loads((study / "manifest.json").read_text())
    manifest["config"]["specs"][0] = str(lab / "phi1.toml")
    manifest["config"]["spec_sha256"][0] = sha256_of(lab / "phi1.toml")   # the spec the study ran
    (study / "manifest.json").write_text(json.dumps(manifest))
    package = tmp_path / "package"
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(package))
    assert code == 0, err
    config = json.loads((package / "study_config.json").read_text())
    assert config["specs"][0] == PATH_LEFT_OUT and (package / config["specs"][1]).is_file()
    assert re.search(r"`config.specs\[0\]`: left out, since it is not a file the installed trustroute "
                     r"package ships", (package / "README.md").read_text())
    assert not [p for p in package.rglob("*") if p.is_file() and b"the lab's own copy" in p.read_bytes()]
    assert_nothing_identifying(package, [str(tmp_path)])


def test_a_package_passed_for_a_study_says_it_is_a_package(model_study, tmp_path, capsys):
    study = shutil.copytree(model_study, tmp_path / "study")   # an export writes its key into the study
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(tmp_path / "package"))
    assert code == 0, err
    package = str(tmp_path / "package")
    for command in (["fit", package, "--out", str(tmp_path / "driver.json")],
                    ["replay", package, "p100-phi1-aware"]):
        code, out, err = run_cli(capsys, *command)
        assert_one_line_error(code, err, str(tmp_path / "package"), "a package `trustroute export` wrote",
                              "the study directory it was exported from", "tables/", "codebook.md")
        assert out == "" and "trustroute study CONFIG" not in err
