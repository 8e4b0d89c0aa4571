"""`trustroute analyze` on a package `trustroute export` wrote: the study's own `--json` figures,
bit for bit, under the package's codes; nothing written into the package; a tampered package
refused; a source the package cannot give said, with why. A simulated study re-run from its
package's copy of its config file: the study's figures again, nothing written into the package."""

from __future__ import annotations

import json
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import pytest

import trustroute.core.package as package_module
import trustroute.harness.study.inputs as inputs_module
from tests.cli import assert_one_line_error, run_cli
from trustroute.core.package import sha256_of
from trustroute.harness.study.inputs import config_sha256

PATHS = ("study_dir", "report_markdown", "report_html", "plots")


def analysed(capsys, folder: Path, *options: str) -> dict:
    code, out, err = run_cli(capsys, "analyze", str(folder), "--json", *options)
    assert code == 0, err
    return json.loads(out)


def exported(capsys, study: Path, package: Path) -> Path:
    code, _, err = run_cli(capsys, "export", str(study), "--out", str(package))
    assert code == 0, err
    return package


@pytest.fixture
def study(model_study, tmp_path) -> Path:
    """A copy of the shared model study: an export writes the study's key into it (export-key.json),
    which the shared study must not carry into other tests."""
    return Path(shutil.copytree(model_study, tmp_path / "study"))


def resummed(package: Path, *left_out: str) -> None:
    """SHA256SUMS written again for the package's files as they are now, without `left_out`: the
    checksums alone no longer tell what changed."""
    sums = package / "SHA256SUMS"
    names = [line.partition("  ")[2] for line in sums.read_text().splitlines()]
    sums.write_text("".join(f"{sha256_of(package / name)}  {name}\n"
                            for name in names if name not in left_out))


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_package_gives_the_study_s_figures_and_stays_as_published(study, tmp_path, capsys):
    package = exported(capsys, study, tmp_path / "package")
    published = files_of(package)
    own, packaged = analysed(capsys, study), analysed(capsys, package)
    assert packaged["study_dir"] == str(package)
    assert {k: v for k, v in packaged.items() if k not in PATHS} == {
        k: v for k, v in own.items() if k not in PATHS}
    assert own["cells"] and own["paired"] and own["sensitivity"]   # figures, not empty tables
    code, _, err = run_cli(capsys, "analyze", str(package))   # printing the tables writes nothing
    assert code == 0, err
    assert files_of(package) == published
    check = subprocess.run(["sha256sum", "-c", "--quiet", "SHA256SUMS"], cwd=package, capture_output=True)
    assert check.returncode == 0, check.stdout


def test_a_package_s_report_goes_only_where_the_user_names(study, tmp_path, capsys, monkeypatch):
    package = exported(capsys, study, tmp_path / "package")
    published = files_of(package)
    code, out, err = run_cli(capsys, "analyze", str(package), "--report")
    assert_one_line_error(code, err, str(package), "--out", "read-only")
    code, out, err = run_cli(capsys, "analyze", str(package), "--out", str(package / "report"))
    assert_one_line_error(code, err, str(package / "report"), "--out", "read-only")
    assert files_of(package) == published
    hashed: Counter[str] = Counter()

    def counted(path: Path) -> str:
        hashed[str(path)] += 1
        return sha256_of(path)

    # the command checks the package once: each file SHA256SUMS lists hashed once, for the
    # analysis and the report's second analysis together, inputs/ not again against the manifest
    monkeypatch.setattr(package_module, "sha256_of", counted)
    monkeypatch.setattr(inputs_module, "sha256_of", counted)
    code, out, err = run_cli(capsys, "analyze", str(package), "--out", str(tmp_path / "report"))
    assert code == 0, err
    listed = [line.partition("  ")[2] for line in (package / "SHA256SUMS").read_text().splitlines()]
    assert hashed == Counter(str(package / name) for name in listed)
    assert (tmp_path / "report" / "report.md").is_file() and (tmp_path / "report" / "plots").is_dir()
    assert files_of(package) == published


def test_a_tampered_package_is_refused_naming_the_file(study, tmp_path, capsys):
    package = exported(capsys, study, tmp_path / "package")
    roads = package / "tables" / "roads.parquet"
    roads.write_bytes(roads.read_bytes() + b"\0")
    code, out, err = run_cli(capsys, "analyze", str(package), "--json")
    assert_one_line_error(code, err, str(roads), "SHA256SUMS")
    assert out == ""


def test_a_package_table_naming_a_road_its_town_lacks_gives_a_package_s_fix(study, tmp_path, capsys):
    """A table whose sums were written again over an edit that names a road the town lacks: one line
    naming the file, the row and the package's fix, not a study directory's (rerun the study)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    package = exported(capsys, study, tmp_path / "package")
    roads = package / "tables" / "roads.parquet"
    table = pq.read_table(roads)
    frame = table.to_pandas()
    frame.loc[0, "directed_road"] = "NO-WHERE"
    pq.write_table(pa.Table.from_pandas(frame, schema=table.schema, preserve_index=False), roads)
    resummed(package)
    code, out, err = run_cli(capsys, "analyze", str(package), "--json")
    assert_one_line_error(code, err, str(roads), "directed_road, row 0")
    assert "get the package again" in err and "rerun `trustroute study`" not in err and out == ""


@pytest.mark.slow
def test_true_source_of_drivers_by_number_is_said_not_available(pilot_study, tmp_path, capsys):
    # a [population]: each participant's driver sampled by their number; a copy, as an export
    # writes the study's key into it
    study = Path(shutil.copytree(pilot_study(5), tmp_path / "study"))
    package = exported(capsys, study, tmp_path / "package")
    on_study, on_package = (analysed(capsys, folder, "--belief-source", "reported")
                            for folder in (study, package))
    assert "true" in {row["source"] for row in on_study["sensitivity"]}
    assert "true" not in {row["source"] for row in on_package["sensitivity"]}
    assert "pseudonymous codes hide" in on_package["belief_source_note"]
    assert on_study["belief_source_note"] == ""
    kept = {k for k in on_study if k not in (*PATHS, "sensitivity", "belief_source_note")}
    assert {k: on_package[k] for k in kept} == {k: on_study[k] for k in kept}
    assert on_package["sensitivity"] == [r for r in on_study["sensitivity"] if r["source"] != "true"]
    default = analysed(capsys, package)
    assert default["belief_source"] == "reported" and "'true'" in default["belief_source_note"]
    code, _, err = run_cli(capsys, "analyze", str(package), "--json", "--belief-source", "true")
    assert_one_line_error(code, err, "--belief-source", "pseudonymous codes hide")


def test_a_package_is_checked_against_what_its_manifest_records(study, tmp_path, capsys):
    """With its checksums rewritten to match, a package that lost a stored input (a spec, which
    the packaged one of its name would stand in for, or the driver model), or whose manifest's
    config was edited, is refused in one line naming the input or the config."""
    package = exported(capsys, study, tmp_path / "package")
    recorded = json.loads((package / "study_manifest.json").read_text())["inputs"]["files"]
    for ending in ("/phi2.toml", "/driver_model.json"):
        copy = Path(shutil.copytree(package, tmp_path / ending.strip("/")))
        name = next(name for name in recorded if name.endswith(ending))
        (copy / name).unlink()
        resummed(copy, name)
        code, out, err = run_cli(capsys, "analyze", str(copy), "--json")
        assert_one_line_error(code, err, name, "the package's manifest records is missing from SHA256SUMS")
        assert out == ""
    manifest_path = package / "study_manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["config"]["participants"] += 1
    manifest_path.write_text(json.dumps(manifest))
    resummed(package)
    code, out, err = run_cli(capsys, "analyze", str(package), "--json")
    assert_one_line_error(code, err, str(manifest_path), "config", "inputs.config_sha256")
    assert out == ""


@pytest.mark.parametrize(("key", "value"), [("town", "town01_carla.json"),
                                            ("specs", ["inputs/../../elsewhere/phi1.toml", "phi2"])])
def test_an_edited_package_s_manifest_is_named_as_the_package_s_own(key, value, study, tmp_path, capsys):
    """A package whose manifest's config was edited (its hash and checksums written again over the
    edit) to name an input outside its inputs/: one line naming the package's own
    study_manifest.json, the key, and the package's fix, never a manifest.json it does not have nor
    a study directory's fix."""
    package = exported(capsys, study, tmp_path / "package")
    manifest_path = package / "study_manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["config"][key] = value
    manifest["inputs"]["config_sha256"] = config_sha256(manifest["config"])
    manifest_path.write_text(json.dumps(manifest))
    resummed(package)
    code, out, err = run_cli(capsys, "analyze", str(package), "--json")
    place = "config.town" if key == "town" else "config.specs"
    assert_one_line_error(code, err, f"{manifest_path}: {place}", "get the package again")
    assert "manifest.json from the study directory" not in err and f"{package}/manifest.json" not in err
    assert out == ""


def test_a_package_whose_export_left_a_spec_out_says_so(tmp_path, capsys):
    """A study (here an import, which stores no copy of its inputs) that ran a spec of the lab's disk:
    the export does not read it, so its package names the spec by the export's placeholder. Analysing
    the package says the export left the spec out and the package cannot be analysed without it,
    with a fix that can work (ask the authors, analyse the study directory): not that the spec is
    "gone", nor to get the package again, which would hold no more."""
    from trustroute.core.packaged import PACKAGED_SPECS
    from trustroute.harness.study.export_inputs import PATH_LEFT_OUT

    lab = tmp_path / "lab" / "phi1.toml"
    lab.parent.mkdir()
    lab.write_text((PACKAGED_SPECS / "phi1.toml").read_text() + "# the lab's own copy\n")
    study = Path(shutil.copytree("analysis/data/real_study/study", tmp_path / "study"))
    manifest = json.loads((study / "manifest.json").read_text())
    manifest["config"]["specs"][0] = str(lab)
    manifest["config"]["spec_sha256"][0] = sha256_of(lab)
    (study / "manifest.json").write_text(json.dumps(manifest))
    package = exported(capsys, study, tmp_path / "package")
    assert json.loads((package / "study_config.json").read_text())["specs"][0] == PATH_LEFT_OUT
    code, out, err = run_cli(capsys, "analyze", str(package), "--json")
    assert_one_line_error(code, err, f"{package / 'study_manifest.json'}: config.specs[0]: the export left "
                          "out this spec of the study", "cannot be analysed again without it",
                          "ask the study's authors for the spec, or analyse the study directory")
    assert "gone" not in err and "get the package again" not in err and out == ""


def test_out_is_the_report_s_folder_alike_at_the_cli_and_the_api(study, tmp_path, capsys):
    """--out (`out=`) names where the report goes: with --no-report (report=False) nothing is
    written, so a folder in the package is neither used nor refused, at the CLI as at the API; a
    report asked there (or by naming the folder alone) is refused at both, before any work."""
    import trustroute
    from trustroute.core.errors import InputError

    package = exported(capsys, study, tmp_path / "package")
    published, inside = files_of(package), package / "report"
    by_cli = analysed(capsys, package, "--no-report", "--out", str(inside))
    by_api = trustroute.analyze(package, report=False, out=inside)
    assert json.loads(json.dumps(by_api.to_dict(), default=str))["cells"] == by_cli["cells"]
    assert by_cli["cells"] and "report_markdown" not in by_cli
    for asked in ([], ["--report"]):
        code, out, err = run_cli(capsys, "analyze", str(package), "--json", "--out", str(inside), *asked)
        assert_one_line_error(code, err, str(inside), "--out", "read-only")
        with pytest.raises(InputError, match="out: the report folder lies in the package"):
            trustroute.analyze(package, report=True if asked else None, out=inside)
    assert files_of(package) == published and not inside.exists()


def test_a_package_whose_drivers_cannot_be_rebuilt_says_so(study, tmp_path, capsys):
    # the model study's drivers are all the nominal model: no number is needed to rebuild them, so
    # a package whose config no trustroute can rebuild lacks "true" for that reason, not its codes
    package = exported(capsys, study, tmp_path / "package")
    # as a later trustroute would export it: its manifest records the hash of the config it holds
    manifest_path = package / "study_manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["config"]["setting_of_a_later_trustroute"] = 1
    manifest["inputs"]["config_sha256"] = config_sha256(manifest["config"])
    manifest_path.write_text(json.dumps(manifest))
    resummed(package)
    note = analysed(capsys, package, "--belief-source", "reported")["belief_source_note"]
    assert "cannot rebuild" in note and "pseudonymous codes" not in note


def test_a_package_without_a_manifest_is_refused(study, tmp_path, capsys):
    package = exported(capsys, study, tmp_path / "package")
    shutil.copytree(package, tmp_path / "old")
    sums = tmp_path / "old" / "SHA256SUMS"
    sums.write_text("".join(line + "\n" for line in sums.read_text().splitlines()
                            if not line.endswith("study_manifest.json")))
    code, _, err = run_cli(capsys, "analyze", str(tmp_path / "old"), "--json")
    assert_one_line_error(code, err, "study_manifest.json", "export the study again")


def test_a_study_re_run_from_its_package_writes_nothing_into_it(study, tmp_path, capsys, monkeypatch):
    package = exported(capsys, study, tmp_path / "package")
    published = files_of(package)
    folders = sorted(p for p in package.rglob("*") if p.is_dir())
    [config] = package.glob("inputs/*/study.toml")   # the study's config file, as written
    shown = str(config.relative_to(package))
    monkeypatch.chdir(package)   # its `inputs/...` paths are the package's (docs/live_studies.md)
    for out in (("--out", str(package / "rerun")), ()):   # in the package: the config's default too
        code, _, err = run_cli(capsys, "study", shown, *out, "--workers", "1", "--no-report")
        assert_one_line_error(code, err, f"in the package {package}", "outside the package")
    code, _, err = run_cli(capsys, "study", shown, "--out", str(tmp_path / "rerun"), "--workers", "1",
                           "--no-report")
    assert code == 0, err
    assert files_of(package) == published   # its policy cache is the user's, not inputs/policies
    assert sorted(p for p in package.rglob("*") if p.is_dir()) == folders
    rerun, own = (analysed(capsys, folder) for folder in (tmp_path / "rerun", study))
    assert {k: v for k, v in rerun.items() if k not in PATHS} == {
        k: v for k, v in own.items() if k not in PATHS}   # the study's own figures, "true" included
