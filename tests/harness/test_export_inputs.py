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
