"""Questionnaire answers of a live study: one JSON file per submitted questionnaire in
`live/questionnaires/` (named after the participant, so a withdrawal finds them) and, from those,
the dataset's `questionnaires.parquet` (QUESTIONNAIRES_SCHEMA), rewritten at every submission.

What is still to be asked follows from the files: the `before` questionnaires until answered, the
`after_each_trial` ones for every done trial, the `end` ones once every trial is done; so a
restarted server asks exactly what is missing.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from trustroute.core.dataset import QUESTIONNAIRES_FILE, QUESTIONNAIRES_SCHEMA, table_from_rows, write_table
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_text
from trustroute.core.validation import read_json
from trustroute.participants.questionnaires import Questionnaire

FOLDER = "live/questionnaires"
ANSWERS_FIX = "restore it from a backup"


def answer_path(study_dir: Path, participant: int, placement: str, trial: str | None, name: str) -> Path:
    return Path(study_dir) / FOLDER / f"p{participant:05d}-{placement}-{trial or 'study'}-{name}.json"


def save_answers(study_dir: Path, participant: int, placement: str, trial: str | None,
                 questionnaire: Questionnaire, answers: dict[str, float]) -> None:
    """One submitted questionnaire (answers already checked); the table rewritten."""
    record = {"participant": participant, "episode_id": trial, "placement": placement,
              "questionnaire": questionnaire.name, "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
              "scale": [questionnaire.minimum, questionnaire.maximum],
              "items": [{"item": item.id, "value": answers[item.id], "reversed": item.reversed}
                        for item in questionnaire.items]}
    path = answer_path(study_dir, participant, placement, trial, questionnaire.name)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(record, indent=1), "questionnaire answers", "free disk space")
    write_answer_table(study_dir)


def answered(study_dir: Path, participant: int, placement: str, trial: str | None, name: str) -> bool:
    return answer_path(study_dir, participant, placement, trial, name).is_file()


def answer_rows(study_dir: Path) -> list[dict]:
    """One row per item answered (QUESTIONNAIRES_SCHEMA's columns), from every answer file in
    file-name order; InputError naming a file that is not a submitted questionnaire's answers."""
    rows = []
    folder = Path(study_dir) / FOLDER
    for path in sorted(folder.glob("p*.json")) if folder.is_dir() else []:
        record = read_json(path, "questionnaire answers", fix=ANSWERS_FIX)
        try:
            if not isinstance(record, dict):
                raise TypeError(record)
            low, high = record["scale"]
            rows += [{"participant": record["participant"], "episode_id": record["episode_id"],
                      "placement": record["placement"], "questionnaire": record["questionnaire"],
                      "item": item["item"], "item_index": index, "value": float(item["value"]),
                      "reversed": bool(item["reversed"]), "scale_min": float(low), "scale_max": float(high),
                      "answered_utc": record["utc"]} for index, item in enumerate(record["items"])]
        except (KeyError, TypeError, ValueError) as exc:
            place = str(exc.args[0]) if isinstance(exc, KeyError) else ""
            raise InputError(str(path), place, "not a submitted questionnaire's answers",
                             ANSWERS_FIX) from None
    return rows


def write_answer_table(study_dir: Path, rows: list[dict] | None = None) -> None:
    """questionnaires.parquet from `rows` (by default every answer file's: `answer_rows`); removed
    when none is left."""
    rows = answer_rows(study_dir) if rows is None else rows
    target = Path(study_dir) / QUESTIONNAIRES_FILE
    if rows:
        write_table(table_from_rows(rows, QUESTIONNAIRES_SCHEMA), target)
    else:
        target.unlink(missing_ok=True)
