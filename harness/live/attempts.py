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
from pathlib import Path

import pyarrow as pa

from trustroute.core.dataset import ATTEMPTS_FILE, ATTEMPTS_SCHEMA, table_from_rows, write_table
from trustroute.harness.study.plan import EpisodeTask

JOURNAL = "attempts.jsonl"


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
        with self.path.open("a", encoding="utf-8") as out:
            out.write(json.dumps(record) + "\n")

    def started(self, task: EpisodeTask, warm_up: bool) -> None:
        self.append({"event": "start", "utc": utc_now(), "participant": task.participant,
                     "episode_id": task.episode_id, "warm_up": warm_up,
                     "planned_position": None if warm_up else task.position})

    def ended(self, task: EpisodeTask, message: dict) -> None:
        outcome, reason = outcome_of(message)
        self.append({"event": "end", "utc": utc_now(), "participant": task.participant,
                     "episode_id": task.episode_id, "outcome": outcome, "reason": reason})

    def records(self) -> list[dict]:
        if not self.path.exists():
            return []
        lines = self.path.read_text(encoding="utf-8").splitlines()
        return [json.loads(line) for line in lines if line.strip()]

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
