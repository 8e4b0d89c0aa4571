"""Every attempt of a live drive, in the order run: `live/attempts.jsonl` (a journal appended as
drives start and end) and, from it, the dataset's `attempts.parquet` (ATTEMPTS_SCHEMA).

A participant's trial may be attempted several times: aborted by the experimenter, failed, or
incomplete (no reconnection in time: the trial moves to the end of the participant's plan). Each
attempt is a row with its place in the participant's sequence, its times, outcome and reason; a
start without an end (the server stopped under it) stays `started`. `run_position` numbers each
participant's done trials in the order they were finished: the order actually run, which
`trustroute analyze` uses for a live study's order effects (analysis/study/order.py).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa

from trustroute.core.dataset import (
    ATTEMPT_OUTCOMES,
    ATTEMPTS_FILE,
    ATTEMPTS_SCHEMA,
    table_from_rows,
    write_table,
)
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_text
from trustroute.core.validation import parse_json, read_input_text
from trustroute.harness.study.plan import EpisodeTask

JOURNAL = "attempts.jsonl"
JOURNAL_FIX = "restore it from a backup or correct that line; attempts.parquet is rebuilt from it"


def _index(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _text(value: object) -> bool:
    return isinstance(value, str)


# The keys of each event of the journal and what each holds (what `AttemptLog.rows` reads).
RECORD_KEYS: dict[str, dict[str, Callable[[object], bool]]] = {
    "start": {"utc": _text, "participant": _index, "episode_id": _text,
              "warm_up": lambda value: isinstance(value, bool),
              "planned_position": lambda value: value is None or _index(value)},
    "end": {"utc": _text, "participant": _index, "episode_id": _text,
            "outcome": lambda value: value in ATTEMPT_OUTCOMES,
            "reason": lambda value: value is None or _text(value)},
}


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def outcome_of(message: dict) -> tuple[str, str | None]:
    """(outcome, reason) of an episode's last message."""
    kind = message.get("type")
    if kind == "episode_end":
        return "done", None
    if kind == "episode_aborted":
        reason = str(message.get("reason", ""))
        return ("incomplete" if reason.startswith("incomplete") else "aborted"), reason
    return "failed", str(message.get("error", ""))


class AttemptLog:
    """The journal of a live study's attempts (callers hold the study's lock)."""

    def __init__(self, study_dir: Path, live_dir: str) -> None:
        self.study_dir = Path(study_dir)
        self.path = self.study_dir / live_dir / JOURNAL

    def append(self, record: dict) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a+b") as out:   # writes go to the end; reads and truncate anywhere
            out.seek(0)
            data = out.read()
            if data and not data.endswith(b"\n"):
                # a crash cut the last append short: the new record starts its own line, and a cut
                # record (not JSON, left out by `entries`) goes
                start = data.rfind(b"\n") + 1
                if _whole(data[start:]):
                    out.write(b"\n")
                else:
                    out.truncate(start)
            out.write((json.dumps(record) + "\n").encode())

    def started(self, task: EpisodeTask, warm_up: bool) -> None:
        self.append({"event": "start", "utc": utc_now(), "participant": task.participant,
                     "episode_id": task.episode_id, "warm_up": warm_up,
                     "planned_position": None if warm_up else task.position})

    def ended(self, task: EpisodeTask, message: dict) -> None:
        outcome, reason = outcome_of(message)
        self.append({"event": "end", "utc": utc_now(), "participant": task.participant,
                     "episode_id": task.episode_id, "outcome": outcome, "reason": reason})

    def entries(self) -> list[tuple[str, dict]]:
        """(line, record) of every attempt journalled, in order, each record checked (`RECORD_KEYS`):
        the one reader of the journal. A last line without its newline that is not JSON is an append
        a crash cut short, and is left out; any other bad line is an InputError naming it."""
        if not self.path.exists():
            return []
        shown = str(self.path)
        text = read_input_text(self.path, "live attempts journal", fix=JOURNAL_FIX)
        lines = text.split("\n")
        entries = []
        for number, line in enumerate(lines, 1):
            if not line.strip():
                continue
            cut = number == len(lines)   # the last line, and no newline after it
            if cut and not _whole(line.encode()):
                break
            entries.append((line, _record(line, shown, number)))
        return entries

    def records(self) -> list[dict]:
        return [record for _, record in self.entries()]

    def rewrite(self, entries: list[tuple[str, dict]]) -> None:
        """The journal holding `entries` (lines of `entries()`) only."""
        atomic_write_text(self.path, "".join(line + "\n" for line, _ in entries), "live attempts",
                          "free disk space")

    def rows(self, drop: set[int] | None = None) -> list[dict]:
        """One row per attempt (ATTEMPTS_SCHEMA's columns), in the journal's order; participants in
        `drop` left out."""
        rows: list[dict] = []
        open_rows: dict[str, dict] = {}
        attempts: dict[str, int] = {}
        sequence: dict[int, int] = {}
        done: dict[int, int] = {}
        for record in self.records():
            participant, episode = int(record["participant"]), str(record["episode_id"])
            if drop and participant in drop:
                continue
            if record["event"] == "start":
                attempts[episode] = attempts.get(episode, 0) + 1
                sequence[participant] = sequence.get(participant, 0) + 1
                row = {"participant": participant, "episode_id": episode, "warm_up": bool(record["warm_up"]),
                       "planned_position": record["planned_position"], "attempt": attempts[episode],
                       "sequence": sequence[participant], "run_position": None,
                       "started_utc": record["utc"], "ended_utc": None, "outcome": "started", "reason": None}
                rows.append(row)
                open_rows[episode] = row
            elif episode in open_rows:
                row = open_rows.pop(episode)
                row.update(ended_utc=record["utc"], outcome=record["outcome"], reason=record["reason"])
                if row["outcome"] == "done" and not row["warm_up"]:
                    row["run_position"] = done.get(participant, 0)
                    done[participant] = row["run_position"] + 1
        return rows

    def table(self) -> pa.Table:
        rows = self.rows()
        return table_from_rows(rows, ATTEMPTS_SCHEMA) if rows else ATTEMPTS_SCHEMA.empty_table()

    def write(self) -> Path:
        return write_table(self.table(), self.study_dir / ATTEMPTS_FILE)


def _whole(line: bytes) -> bool:
    """Whether a journal line is whole JSON (a cut append is not)."""
    try:
        json.loads(line)
    except ValueError:
        return False
    return True


def _record(line: str, shown: str, number: int) -> dict:
    """The journal's record on line `number`, checked; InputError naming the line otherwise."""
    place = f"line {number}"
    try:
        record = parse_json(line, shown, "live attempts journal")
    except InputError as exc:   # placed in the file, not in the line alone
        column = exc.place.partition(" column ")[2]
        raise InputError(shown, f"{place} column {column}" if column else place, exc.problem,
                         JOURNAL_FIX) from None
    if not isinstance(record, dict) or record.get("event") not in RECORD_KEYS:
        raise InputError(shown, place, "not an attempt record (an object whose event is 'start' or 'end')",
                         JOURNAL_FIX)
    for key, accepts in RECORD_KEYS[record["event"]].items():
        if key not in record or not accepts(record[key]):
            raise InputError(shown, f"{place} key {key!r}", "missing" if key not in record else
                             f"unexpected value {json.dumps(record[key])[:40]}", JOURNAL_FIX)
    return record
