"""A study packaged for sharing (`trustroute export STUDY --out DIR`): the consolidated tables
with pseudonymous participant ids, the codebook generated from the dataset schema
(trustroute/core/codebook.py), the study config, the texts participants were shown, the software
versions, checksums of every file and a README. A live study's questionnaires go into
`texts/questionnaires.json` as the station showed them, read from the study's own copies of their
files (harness/study/inputs.py), so the package names no file of the lab's disk.

Pseudonyms: each participant number is replaced by a three-digit code drawn without replacement
(100-999; four digits for a study of more than 900 participants, five for more than 9,000, ...)
from a Generator seeded by the caller, in the `participant` column and in every `episode_id`
(`p<code, 5 digits>-<spec>-<condition>`). The key (original number -> code) is
written into the study directory (`export-key.json`), never into the package. Nothing of the
live registry (token digests, labels), the token log or the withdrawal audit is exported.
"""

from __future__ import annotations

import hashlib
import json
import platform
import re
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa

from trustroute.core.codebook import codebook
from trustroute.core.dataset import MANIFEST_FILE, TABLES, read_manifest, read_study_table, write_table
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_text, check_output_dir
from trustroute.harness.study.inputs import relocated_config
from trustroute.participants.questionnaires import Questionnaire, questionnaire_plan

KEY_FILE = "export-key.json"
TEXTS = {"consent.txt": "live/consent.txt"}   # texts participants were shown: package name <- study path
QUESTIONNAIRES_TEXT = "questionnaires.json"   # the questionnaires participants answered, where asked
EPISODE_PARTICIPANT = re.compile(r"^p(\d{5})-")


def pseudonyms(participants: list[int], rng: np.random.Generator) -> dict[int, int]:
    """Each participant's code, drawn without replacement from the three-digit codes, or from the
    codes of as many more digits as a larger study needs (1000-9999 for up to 9,000, ...)."""
    digits = 3
    while 9 * 10 ** (digits - 1) < len(participants):
        digits += 1
    codes = rng.choice(np.arange(10 ** (digits - 1), 10 ** digits), size=len(participants), replace=False)
    return {int(p): int(code) for p, code in zip(sorted(participants), codes, strict=True)}


def participants_of(study_dir: Path) -> list[int]:
    found: set[int] = set()
    for name, (file_name, schema) in TABLES.items():
        path = Path(study_dir) / file_name
        if path.exists() and "episode_id" in schema.names:
            episodes = read_study_table(study_dir, name, ["episode_id"]).column(0).to_pylist()
            found.update(int(m.group(1)) for e in episodes if e and (m := EPISODE_PARTICIPANT.match(e)))
        if path.exists() and "participant" in schema.names:
            numbers = read_study_table(study_dir, name, ["participant"]).column(0).to_pylist()
            found.update(int(p) for p in numbers)
    return sorted(found)


def pseudonymised(table: pa.Table, key: dict[int, int]) -> pa.Table:
    """`table` with its participant numbers and episode ids under the pseudonyms of `key`."""
    names = table.schema.names
    if "participant" in names:
        index = names.index("participant")
        values = [key[int(p)] for p in table.column(index).to_pylist()]
        table = table.set_column(index, table.schema.field(index), pa.array(values, pa.int64()))
    if "episode_id" in names:
        index = names.index("episode_id")

        def renamed(episode: str | None) -> str | None:
            if episode is None or (match := EPISODE_PARTICIPANT.match(episode)) is None:
                return episode
            return f"p{key[int(match.group(1))]:05d}-{episode[match.end():]}"

        ids = [renamed(e) for e in table.column(index).to_pylist()]
        table = table.set_column(index, table.schema.field(index), pa.array(ids, pa.string()))
    return table


def sha256_of(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def export_study(study_dir: Path, out: Path, rng: np.random.Generator) -> dict:
    """Write the package of `study_dir` into `out` (a new or empty directory); its index."""
    study_dir, out = Path(study_dir), Path(out)
    manifest = read_manifest(study_dir)
    check_output_dir(out, "--out", "package directory")
    if out.exists() and any(out.iterdir()):
        raise InputError(str(out), "--out", "the directory is not empty", "pass a new or empty directory")
    if out.resolve().is_relative_to(study_dir.resolve()):
        raise InputError(str(out), "--out", "the package would be inside the study directory",
                         "pass a directory outside the study")
    shown = questionnaires_shown(manifest, study_dir)   # read before anything is written
    key = pseudonyms(participants_of(study_dir), rng)
    (out / "tables").mkdir(parents=True, exist_ok=True)
    tables = []
    for name, (file_name, _) in TABLES.items():
        path = study_dir / file_name
        if path.exists():
            write_table(pseudonymised(read_study_table(study_dir, name), key), out / "tables" / file_name)
            tables.append(name)
    book = {name: entries for name, entries in codebook().items() if name in tables}
    atomic_write_text(out / "codebook.json", json.dumps(book, indent=1), "codebook")
    atomic_write_text(out / "codebook.md", codebook_markdown(book), "codebook")
    atomic_write_text(out / "study_config.json", json.dumps(manifest["config"], indent=1, default=str),
                      "study config")
    versions = {"python": platform.python_version(), "git_revision": manifest.get("git_revision"),
                "packages": manifest.get("packages", {}), "engine": manifest.get("engine")}
    atomic_write_text(out / "versions.json", json.dumps(versions, indent=1), "software versions")
    texts = []
    for name, source in TEXTS.items():
        if (study_dir / source).is_file():
            (out / "texts").mkdir(exist_ok=True)
            shutil.copyfile(study_dir / source, out / "texts" / name)
            texts.append(name)
    if shown is not None:
        (out / "texts").mkdir(exist_ok=True)
        atomic_write_text(out / "texts" / QUESTIONNAIRES_TEXT, json.dumps(shown, indent=1), "questionnaires")
        texts.append(QUESTIONNAIRES_TEXT)
    atomic_write_text(out / "README.md", readme(manifest, tables, texts, len(key)), "README")
    atomic_write_text(study_dir / KEY_FILE, json.dumps({"pseudonyms": {str(p): c for p, c in key.items()},
                                                        "package": str(out.resolve())}, indent=1),
                      "export key")
    files = sorted(path for path in out.rglob("*") if path.is_file())
    sums = "".join(f"{sha256_of(path)}  {path.relative_to(out)}\n" for path in files)
    atomic_write_text(out / "SHA256SUMS", sums, "checksums")
    return {"tables": tables, "texts": texts, "participants": len(key), "files": len(files) + 1}


def questionnaires_shown(manifest: dict, study_dir: Path) -> dict | None:
    """What each questionnaire of a live study asked where it was placed ({placement: [the station's
    questionnaire, with each item's `reversed`]}), read from the study's own copies of its files;
    None for a study without questionnaires."""
    config = relocated_config(manifest.get("config") or {}, study_dir)
    if not config.get("questionnaires"):
        return None
    try:
        plan = questionnaire_plan(config["questionnaires"], study_dir, str(study_dir / MANIFEST_FILE))
    except InputError as error:   # a study consolidated before its questionnaire files were stored
        raise InputError(str(study_dir / MANIFEST_FILE), "config.questionnaires",
                         f"a questionnaire the study names cannot be read ({error.source}: {error.problem})",
                         "put the file back where the manifest names it, so that its texts are exported"
                         ) from None

    def shown(questionnaire: Questionnaire, placement: str) -> dict:
        asked = questionnaire.to_client(placement)
        reversed_ids = {item.id for item in questionnaire.items if item.reversed}
        items = [{**item, "reversed": item["id"] in reversed_ids} for item in asked["items"]]
        return {**asked, "items": items}

    return {placement: [shown(q, placement) for q in found] for placement, found in plan.items()}


def codebook_markdown(book: dict[str, list[dict]]) -> str:
    lines = ["# Codebook", ""]
    for table, entries in book.items():
        lines += [f"## {table} (`tables/{entries[0]['file']}`)", "",
                  "| column | type | null allowed | unit | meaning | allowed values |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| `{e['column']}` | {e['type']} | {'yes' if e['nullable'] else 'no'} | {e['unit']} | "
                  f"{e['meaning']} | {e['allowed']} |" for e in entries]
        lines.append("")
    return "\n".join(lines)


def readme(manifest: dict, tables: list[str], texts: list[str], participants: int) -> str:
    name = manifest.get("study", "the study")
    return "\n".join([
        f"# {name}: data package", "",
        f"A trustroute study ({manifest.get('engine')} engine) of {participants} participant(s), "
        "exported with `trustroute export`.", "",
        "- `tables/`: the consolidated tables (Apache Parquet): " + ", ".join(tables) + ".",
        "- `codebook.md`, `codebook.json`: every column's type, whether it may be null, unit, meaning and "
        "allowed values.",
        "- `study_config.json`: the study's configuration; `versions.json`: the software that made it.",
        "- `texts/`: what participants were shown (" + (", ".join(texts) or "none recorded") + ")"
        + (f"; `{QUESTIONNAIRES_TEXT}`: per placement (`before`, `after_each_trial`, `end`) each "
           "questionnaire as the station showed it (title, instructions, scale, items; an item's `id` is "
           "the `item` of the questionnaires table, `reversed` items are scored as min + max - value)"
           if QUESTIONNAIRES_TEXT in texts else "") + ".",
        "- `SHA256SUMS`: the SHA-256 of every other file (`sha256sum -c SHA256SUMS`).", "",
        "Participants are pseudonymous: each participant number is a random three-digit code, in the "
        "`participant` column and in every `episode_id` (`p<code>-<spec>-<condition>`). Missing values "
        "are nulls.", ""])
