"""The export's reading of a study's inputs (harness/study/export_inputs.py), unit by unit: an
absolute path naming the lab's account is rewritten like any other, not a reason to leave the file
out; a stored input is one of the study's inputs/, however a symbolic link in it leads."""

from __future__ import annotations

from trustroute.harness.study.export_inputs import PATH_LEFT_OUT, cleaned, within

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
