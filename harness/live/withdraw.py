"""A participant's withdrawal from a live study: their data deleted, the deletion audited.

`withdraw_participant` (the caller holds the study directory's lock: `trustroute withdraw`
takes it, the live server holds it already) removes every file of the participant (their
trials' parts and failures, their warm-up drives, recordings, questionnaire answers), their
attempts from the journal, and their label and token from `live/participants.json` (the record
stays, marked withdrawn, so their index is not reused and a re-run is refused until
`readmit_participant`); then the dataset is consolidated again without them, and an audit entry
is appended to `live/withdrawals.jsonl`: who, when, why, every file removed with its SHA-256 and
size, the SHA-256 of every consolidated table before and after, and, when packages exported
before hold the participant (`exported_as`), each of those packages and their code in it: the
withdrawal cannot reach a package already shared, so it says which ones to replace.
"""

from __future__ import annotations

import getpass
import json
import re
import time
from dataclasses import dataclass
from pathlib import Path

from trustroute.core.dataset import ATTEMPTS_FILE, FAILURES_DIR, MANIFEST_FILE, PARTS_DIR, TABLES
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_text
from trustroute.core.package import sha256_of
from trustroute.core.validation import read_json
from trustroute.core.wording import counted
from trustroute.harness.live.answers import answer_rows, write_answer_table
from trustroute.harness.live.attempts import AttemptLog
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.context import StudyContext, study_context
from trustroute.harness.study.export import read_export_keys
from trustroute.harness.study.manifest import consolidate
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.replay import study_config_from_manifest

LIVE_DIR = "live"
REGISTRY = "participants.json"
AUDIT = "withdrawals.jsonl"
# Folders holding one file per episode id (the participant's start with p<5 digits>-).
PARTICIPANT_FOLDERS: tuple[str, ...] = (PARTS_DIR, FAILURES_DIR, "recordings", "live/warmup/parts",
                                        "live/questionnaires")


def participant_files(study_dir: Path, participant: int) -> list[Path]:
    prefix = f"p{participant:05d}-"
    found: list[Path] = []
    for folder in PARTICIPANT_FOLDERS:
        if (Path(study_dir) / folder).is_dir():
            found += [path for path in (Path(study_dir) / folder).iterdir()
                      if path.name.startswith(prefix) and path.is_file() and not path.is_symlink()]
    return sorted(found)


def table_checksums(study_dir: Path) -> dict[str, str]:
    """SHA-256 of each consolidated table present."""
    names = [file_name for file_name, _ in TABLES.values()]
    return {name: sha256_of(Path(study_dir) / name) for name in names if (Path(study_dir) / name).is_file()}


def read_registry(study_dir: Path) -> dict:
    """The study's participant registry (`load_registry`); InputError when there is none."""
    path = Path(study_dir) / LIVE_DIR / REGISTRY
    if not path.exists():
        raise InputError(str(study_dir), f"{LIVE_DIR}/{REGISTRY}", "not a live study with participants",
                         "pass the directory of a live study (trustroute live)")
    return load_registry(path, "restore it from a backup")


# A participant's index as a registry key: 0, 1, 2, ... (what `trustroute withdraw` accepts)
PARTICIPANT_KEY = re.compile(r"0|[1-9][0-9]{0,8}")


def load_registry(path: Path, fix: str) -> dict:
    """A participant registry (`live/participants.json`), checked wherever it is read: an object
    whose "participants" maps each participant's index ("0", "1", ...) to their record, an object
    (its "order", when given, a list of episode ids); InputError naming the key otherwise."""
    records = read_json(path, "live participants", fix=fix)
    if not isinstance(records, dict) or not isinstance(records.get("participants"), dict):
        raise InputError(str(path), "participants", "not a participant registry", fix)
    for key, record in records["participants"].items():
        place = f"participants.{key}"
        if not PARTICIPANT_KEY.fullmatch(key):
            raise InputError(str(path), place, "not a participant's index (0, 1, 2, ...)", fix)
        if not isinstance(record, dict):
            raise InputError(str(path), place, f"expected an object (the participant's record), got "
                             f"{json.dumps(record)[:40]}", fix)
        order = record.get("order", [])
        if not isinstance(order, list) or not all(isinstance(episode, str) for episode in order):
            raise InputError(str(path), f"{place}.order", "expected a list of episode ids", fix)
    return records


def registry_records(study_dir: Path) -> list[dict] | None:
    """Every participant's record in a live study's registry (`load_registry`); None for a study
    without a registry (a simulated one)."""
    path = Path(study_dir) / LIVE_DIR / REGISTRY
    if not path.exists():
        return None
    return list(load_registry(path, "restore it from a backup")["participants"].values())


ENDED = ("withdrawn", "declined")   # the registry's marks of a participant with no data


def ended_counts(records: list[dict] | None) -> dict[str, int] | None:
    """How many of a live study's participants are withdrawn (not readmitted) and how many declined
    the consent (not asked again since), as its registry's `records` say (`registry_records`):
    {"withdrawn": n, "declined": m}; None for a study without a registry (a simulated one).
    `trustroute export` reports the counts."""
    if records is None:
        return None
    return {ended: sum(1 for record in records if record.get(ended)) for ended in ENDED}


def registry_words(records: list[dict] | None) -> list[tuple[str, str]]:
    """The words of a live study's registry `records` (`registry_records`) that name a participant,
    with what each is: every label and token digest ([] for a study without a registry).
    `trustroute export` keeps them out of the package's copied inputs
    (harness/study/export_inputs.py)."""
    kinds = (("label", "a participant's label"), ("digest", "a participant's token digest"))
    return [(str(record[key]), what) for record in records or []
            for key, what in kinds if record.get(key)]


def write_registry(study_dir: Path, records: dict) -> None:
    atomic_write_text(Path(study_dir) / LIVE_DIR / REGISTRY, json.dumps(records, indent=1),
                      "live participants", "free disk space")


def registry_record(study_dir: Path, records: dict, participant: int) -> dict:
    record = records["participants"].get(str(participant))
    if record is None:
        raise InputError(str(study_dir), "PARTICIPANT", f"no participant {participant} in this study",
                         f"pass one of {', '.join(sorted(records['participants'], key=int)) or 'none'}")
    return record


def declined(participant: int) -> tuple[str, str]:
    """(problem, fix): why nothing is done for a participant who did not agree to take part:
    nothing of theirs is kept (harness/live/server.py, `LiveStudy.decline`)."""
    return f"participant {participant} did not agree to take part", "nothing to do: nothing of theirs is kept"


def declined_refusal(study_dir: Path, participant: int) -> InputError:
    """The refusal to withdraw a participant who did not agree to take part."""
    return InputError(str(study_dir), "PARTICIPANT", *declined(participant))


def exported_as(study_dir: Path, participant: int) -> list[dict]:
    """[{"package", "written_utc", "participant"}]: every package `trustroute export` wrote from
    this study that holds the participant, when it was written and their code in it, as the study's
    key file says (harness/study/export.py, `read_export_keys`); [] when none does. Their data stay
    in a package already shared until the study is exported again without them."""
    return [{"package": entry["package"], "written_utc": entry["written_utc"], "participant": code}
            for entry in read_export_keys(study_dir)
            if (code := entry["pseudonyms"].get(str(participant))) is not None]


def still_exported(exported: list[dict]) -> str:
    """What the withdrawal's line says of the packages exported before that hold the participant
    (`exported_as`): each one and their code in it, to be replaced; each with when it was written,
    where known, since two packages written to one path have two keys."""
    if len(exported) == 1:
        return (f"the package exported before, {package_named(exported[0])}, still holds their data as "
                f"participant {exported[0]['participant']}: export the study again and replace it "
                "wherever it was shared")
    held = ", ".join(f"{package_named(package)} as participant {package['participant']}"
                     for package in exported)
    return (f"the {len(exported)} packages exported before still hold their data ({held}): export the "
            "study again and replace each wherever it was shared")


def package_named(exported: dict) -> str:
    """An exported package in the withdrawal's line: its path, and when it was written where known."""
    written = exported["written_utc"]
    return exported["package"] if written is None else f"{exported['package']} (written {written})"


def withdrawal_line(study_dir: Path, entry: dict) -> str:
    """The line that tells the experimenter what the withdrawal of the audit `entry` did and, where
    packages exported before still hold the participant, which ones to replace (`trustroute
    withdraw` prints it; the console shows it)."""
    removed = counted(len(entry["removed"]), "file")
    line = (f"participant {entry['participant']} withdrawn: {removed} removed, "
            f"the dataset consolidated without them; audit entry in {Path(study_dir) / LIVE_DIR / AUDIT}")
    return f"{line}; {still_exported(entry['exported'])}" if "exported" in entry else line


@dataclass
class WithdrawalInputs:
    """Everything a withdrawal reads, read and checked (`read_withdrawal`) before it changes anything."""

    records: dict                  # the registry
    config: StudyConfig | None     # the study's config and manifest, once consolidated
    manifest: dict
    context: StudyContext | None
    journal: AttemptLog
    attempts: list[tuple[str, dict]]   # the journal's entries of the other participants
    answers: list[dict]                # the questionnaires' rows of the other participants
    exported: list[dict]               # the packages exported before that hold the participant


def read_withdrawal(study_dir: Path, participant: int) -> WithdrawalInputs:
    """Read and check everything the withdrawal of `participant` needs (the registry, the manifest
    and the study's inputs, the attempts journal, the answers, the export key); InputError, with
    nothing changed, when a file cannot be read or the participant cannot withdraw. The console
    calls it before the participant's session ends, so that such a file leaves them as they were."""
    study_dir = Path(study_dir)
    records = read_registry(study_dir)
    record = registry_record(study_dir, records, participant)
    if record.get("withdrawn"):
        raise InputError(str(study_dir), "PARTICIPANT", f"participant {participant} has withdrawn already",
                         "nothing to do (see live/withdrawals.jsonl)")
    if record.get("declined"):
        raise declined_refusal(study_dir, participant)
    consolidated = (study_dir / MANIFEST_FILE).exists()   # nothing to consolidate before a first episode
    config, manifest = study_config_from_manifest(study_dir) if consolidated else (None, {})
    context = study_context(config) if config is not None else None
    journal = AttemptLog(study_dir, LIVE_DIR)
    attempts = [entry for entry in journal.entries() if entry[1]["participant"] != participant]
    answers = [row for row in answer_rows(study_dir) if row["participant"] != participant]
    return WithdrawalInputs(records, config, manifest, context, journal, attempts, answers,
                            exported_as(study_dir, participant))


def withdraw_participant(study_dir: Path, participant: int, by: str | None = None, reason: str = "") -> dict:
    """Withdraw `participant` (the directory's lock held by the caller); the audit entry. Everything
    it reads is read and checked first (`read_withdrawal`), before a file is removed, so a refusal
    leaves the study as it was."""
    study_dir = Path(study_dir)
    read = read_withdrawal(study_dir, participant)
    before = table_checksums(study_dir)
    files = participant_files(study_dir, participant)
    removed = [{"path": str(path.relative_to(study_dir)), "sha256": sha256_of(path),
                "bytes": path.stat().st_size} for path in files]
    for path in files:
        path.unlink()
    if read.journal.path.exists():
        read.journal.rewrite(read.attempts)
    withdrawn_utc = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    read.records["participants"][str(participant)] = {"withdrawn": True, "withdrawn_utc": withdrawn_utc}
    write_registry(study_dir, read.records)
    if read.config is not None and read.context is not None:
        consolidate(study_dir, read.context, plan_episodes(read.config), read.manifest["config_hash"],
                    read.manifest.get("expected"), read.manifest.get("run"))
    if (study_dir / ATTEMPTS_FILE).exists() or read.journal.path.exists():
        read.journal.write()
    write_answer_table(study_dir, read.answers)
    entry = {"utc": withdrawn_utc,
             "by": by or getpass.getuser(), "participant": participant, "reason": reason,
             "removed": removed, "tables_before": before, "tables_after": table_checksums(study_dir),
             **({"exported": read.exported} if read.exported else {})}
    with (study_dir / LIVE_DIR / AUDIT).open("a", encoding="utf-8") as out:
        out.write(json.dumps(entry) + "\n")
    return entry


def readmit_participant(study_dir: Path, participant: int, by: str | None = None) -> dict:
    """Allow a withdrawn participant to take part again (with a new link from the console); the
    audit entry."""
    study_dir = Path(study_dir)
    records = read_registry(study_dir)
    if not registry_record(study_dir, records, participant).get("withdrawn"):
        raise InputError(str(study_dir), "PARTICIPANT", f"participant {participant} has not withdrawn",
                         "withdraw them first, or leave them as they are")
    records["participants"][str(participant)] = {"label": "", "consented": False, "readmitted": True}
    write_registry(study_dir, records)
    entry = {"utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "by": by or getpass.getuser(),
             "participant": participant, "readmitted": True}
    with (study_dir / LIVE_DIR / AUDIT).open("a", encoding="utf-8") as out:
        out.write(json.dumps(entry) + "\n")
    return entry
