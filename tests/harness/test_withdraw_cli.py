"""`trustroute withdraw STUDY PARTICIPANT`: PARTICIPANT is the id the dataset writes (p00003) or
its index (3); anything else is one usage line naming both forms."""

from __future__ import annotations

import pytest

from tests.cli import assert_one_line_error, run_cli


@pytest.mark.parametrize("participant", ["p00003", "3", "p3"])
def test_the_participant_is_its_dataset_id_or_its_index(capsys, tmp_path, participant):
    from trustroute.harness.commands.withdraw import Participant

    assert Participant().convert(participant, None, None) == 3
    code, _, err = run_cli(capsys, "withdraw", str(tmp_path), participant)
    assert_one_line_error(code, err, "not a live study")   # the argument passed; the folder did not


@pytest.mark.parametrize("participant", ["px", "-1", "p-1", "q00003", "p0000000003"])
def test_another_participant_is_one_line_naming_both_forms(capsys, tmp_path, participant):
    code, _, err = run_cli(capsys, "withdraw", str(tmp_path), "--", participant)
    assert_one_line_error(code, err, f"{participant!r} is not a participant", "(p00003) or its index (3)")
