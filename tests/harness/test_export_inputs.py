"""The export's reading of a study's inputs (harness/study/export_inputs.py), unit by unit: an
absolute path naming the lab's account is rewritten like any other, not a reason to leave the file
out; a path is rewritten to the copy it names, never to a place in a copied folder the package
does not hold; a stored input is one of the study's inputs/, however a symbolic link in it leads."""

from __future__ import annotations

from trustroute.harness.study.export_inputs import PATH_LEFT_OUT, cleaned, path_map, rewritten_paths, within

ACCOUNT = [("alice", "the user name of the account that runs the export")]


def test_a_path_under_the_accounts_home_folder_is_rewritten_and_the_file_kept():
    text = '{"source": "fitted by `trustroute fit /home/alice/pilot` beside /home/alice/lab/spec.toml"}'
    mapped = {"/home/alice/lab/spec.toml": "inputs/0123456789abcdef/spec.toml"}
    kept, said, why = cleaned(text, mapped, ACCOUNT, {})
    assert why is None
    assert kept == (f'{{"source": "fitted by `trustroute fit {PATH_LEFT_OUT}` beside '
                    'inputs/0123456789abcdef/spec.toml"}')
    assert said is not None and "alice" not in kept


def test_the_accounts_name_outside_a_path_still_leaves_the_file_out():
    text = "# run by alice from /home/alice/lab\n"
    assert cleaned(text, {}, ACCOUNT, {})[2] == "it holds the user name of the account that runs the export"


def test_a_symbolic_link_in_inputs_to_another_file_of_the_study_is_not_followed(tmp_path):
    study = tmp_path / "study"
    folder = study / "inputs" / "0123456789abcdef"
    folder.mkdir(parents=True)
    (study / "export-key.json").write_text('{"packages": []}')
    (folder / "spec.toml").symlink_to(study / "export-key.json")
    (folder / "town.json").write_text("{}")
    assert within(study, "inputs/0123456789abcdef/spec.toml") is None
    assert within(study, "inputs/0123456789abcdef/town.json") == folder / "town.json"
    assert within(study, "inputs/../export-key.json") is None


def test_a_path_inside_a_copied_folder_naming_no_copy_is_left_out_not_rewritten_into_it():
    """The policy cache's folder was copied (inputs/policies): the folder and each copied file are
    named by their copies; a path in that folder naming a file the package does not hold is the
    mark, not an `inputs/policies/...` path that does not exist and carries the lab's file names."""
    copy = {"sha256": "0" * 64, "source": "/lab/cache/aware-1.json"}
    mapped = path_map({"inputs/policies/aware-1.json": copy})
    text = ("cache /lab/cache and /lab/cache/, policy /lab/cache/aware-1.json, "
            "notes /lab/cache/jane_doe/notes.txt")
    assert rewritten_paths(text, mapped) == (
        "cache inputs/policies and inputs/policies/, policy inputs/policies/aware-1.json, "
        f"notes {PATH_LEFT_OUT}", 3, 1)


def test_a_text_input_not_in_utf8_is_left_out_not_copied_unread(tmp_path):
    """A background-routes file in Latin-1 (SUMO reads the encoding its XML declares) cannot be read
    as the export reads text: it is left out, with why, rather than copied with the lab's paths in
    it; a decision table (a zip archive) is still copied as the binary it is."""
    from trustroute.harness.study.export_inputs import export_inputs

    study, out = tmp_path / "study", tmp_path / "package"
    routes = ('<?xml version="1.0" encoding="ISO-8859-1"?>\n<!-- net /home/alice/lab/town.net.xml, '
              'Stra\xdfe -->\n<routes/>\n').encode("latin-1")
    files = {"inputs/0123456789abcdef/bg.rou.xml": routes,
             "inputs/policies/aware-1.npz": b"PK\x03\x04" + bytes(range(256))}
    for relative, data in files.items():
        (study / relative).parent.mkdir(parents=True, exist_ok=True)
        (study / relative).write_bytes(data)
    manifest = {"config": {"routes": ["inputs/0123456789abcdef/bg.rou.xml"]},
                "inputs": {"files": {relative: {"sha256": "0" * 64, "source": f"/home/alice/lab/{i}"}
                                     for i, relative in enumerate(files)}}}
    packaged = export_inputs(study, manifest, out, {}, [])
    assert not (out / "inputs/0123456789abcdef/bg.rou.xml").exists()
    assert "UTF-8" in packaged.left_out["inputs/0123456789abcdef/bg.rou.xml"]
    assert (out / "inputs/policies/aware-1.npz").read_bytes() == files["inputs/policies/aware-1.npz"]


def test_the_config_names_the_copies_its_inputs_record_says():
    """The package's config is rewritten by the paths its record maps, whoever filled the record."""
    import json

    from trustroute.harness.study.export_inputs import PackagedInputs, config_text

    copy = {"sha256": "0" * 64, "source": "/lab/towns/grid.json"}
    packaged = PackagedInputs(record={"inputs/0000000000000000/grid.json": copy})
    config = json.loads(config_text({"town": "/lab/towns/grid.json", "specs": ["/lab/gone.json"]}, packaged))
    assert config == {"town": "inputs/0000000000000000/grid.json", "specs": [PATH_LEFT_OUT]}
