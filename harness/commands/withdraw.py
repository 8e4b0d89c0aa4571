"""`trustroute withdraw STUDY PARTICIPANT`: a participant of a live study withdraws; their data is
deleted and the deletion audited (harness/live/withdraw.py; docs/live_studies.md, "Withdrawal").

The study directory's lock is taken first, so a running `trustroute live` on it is refused
(withdraw from its console instead). `--readmit` lets a withdrawn participant take part again.
"""

from __future__ import annotations

import re
from pathlib import Path

import click

from trustroute.core.wording import shown_value
from trustroute.harness.commands.options import UsageFix
from trustroute.harness.commands.output import emit, json_option, with_paths

PARTICIPANT = re.compile(r"p?([0-9]{1,9})")


class Participant(click.ParamType):
    """A participant of a live study: its id as the dataset writes it (p00003, `p` and the index)
    or its index (3); both name the same participant."""

    name = "participant"

    def convert(self, value, param, ctx):
        if isinstance(value, int):
            return value
        match = PARTICIPANT.fullmatch(str(value).strip())
        if match is None:
            raise UsageFix(f"{shown_value(value)} is not a participant",
                           "pass the participant's id as in the dataset (p00003) or its index (3)", ctx)
        return int(match.group(1))


@click.command("withdraw")
@click.argument("study_dir", metavar="STUDY", type=click.Path())
@click.argument("participant", metavar="PARTICIPANT", type=Participant())
@click.option("--reason", default="", help="Why (recorded in the audit entry).")
@click.option("--by", default=None, help="Who withdraws them (default: the user running the command).")
@click.option("--readmit", is_flag=True, help="Instead: let a withdrawn participant take part again.")
@json_option
def withdraw(study_dir: str, participant: int, reason: str, by: str | None, readmit: bool,
             as_json: bool) -> None:
    """Delete PARTICIPANT's drives, warm-ups, answers and rows from the live study STUDY.

    PARTICIPANT is the participant's id as in the dataset (p00003) or its index (3)."""
    from trustroute.core.errors import InputError
    from trustroute.harness.live.withdraw import (
        AUDIT,
        LIVE_DIR,
        REGISTRY,
        readmit_participant,
        withdraw_participant,
        withdrawal_line,
    )
    from trustroute.harness.study.runner import held_study

    path = Path(study_dir)
    if not path.is_dir():
        raise InputError(study_dir, "", "no such study directory", "pass the directory of a live study")
    with held_study(path, "withdraw from the live console while its server runs, or wait for that run "
                          "to finish"):
        entry = (readmit_participant(path, participant, by) if readmit
                 else withdraw_participant(path, participant, by, reason))
    audit = path / LIVE_DIR / AUDIT
    # the audit entry appended, the registry rewritten; a withdrawal also consolidates the tables again
    written = {"audit": audit, "registry": path / LIVE_DIR / REGISTRY, "study": None if readmit else path}
    line = (f"participant {participant} readmitted (a new link from the console lets them in)" if readmit
            else withdrawal_line(path, entry))
    emit(as_json, with_paths(entry, written), [line])
