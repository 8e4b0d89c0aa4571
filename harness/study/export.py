"""A study packaged for sharing (`trustroute export STUDY --out DIR`): the consolidated tables
with pseudonymous participant ids, the codebook generated from the dataset schema
(trustroute/core/codebook.py), the study config, the texts participants were shown, the software
versions, checksums of every file and a README. A live study's questionnaires go into
`texts/questionnaires.json` as the station showed them, read from the study's own copies of their
files (harness/study/inputs.py), so the package names no file of the lab's disk.

Pseudonyms: each participant number is replaced by a three-digit code drawn without replacement
(100-999; four digits for a study of more than 900 participants, five for more than 9,000, ...)
from a Generator seeded by the caller, in the `participant` column and in every `episode_id`
(`p<code, 5 digits>-<spec>-<condition>`; an imported study's ids, such as `d04-t1-aware`, which
carry the driver's number, are renamed so from the episodes table). The key (original number -> code) is
written into the study directory (`export-key.json`), never into the package: one entry per
package written (its resolved path, when it was written, the key), so that a withdrawal
(harness/live/withdraw.py) names every package shared with the participant's data in it, not only
the newest; an export to the same path again replaces that path's entry only when the key is the
same (an earlier package there, of another key, may have been shared before the path was emptied).
Nothing of the live registry (token digests, labels), the token log or the withdrawal audit is exported.

Neither is the order of enrolment or the lab's schedule: every table's rows are sorted by pseudonym
(a participant's rows in the table's own order), and every wall-clock column becomes the seconds
since the participant's first recorded wall-clock time (trustroute/core/package.py, EXPORTED_TIMES).
The README reports the participant flow (planned, with data, and for a live study withdrawn,
declined and did not take part: counts adding up to the planned).
"""

from __future__ import annotations

import json
import platform
import re
import shutil
from datetime import datetime
from pathlib import Path

import numpy as np
import pyarrow as pa

from trustroute.core.codebook import (
    CONFIG_WITHOUT_PEOPLE_SEEDS,
    EXPORTED_TIMES,
    WITHOUT_PEOPLE_SEEDS,
    codebook,
    exported_schema,
)
from trustroute.core.dataset import (
    MANIFEST_FILE,
    MANIFEST_KEYS,
    REBUILD_FIX,
    TABLES,
    read_manifest,
    read_study_table,
    write_table,
)
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_text, check_output_dir
from trustroute.core.package import (
    PACKAGE_CONFIG_FILE,
    PACKAGE_MANIFEST_FILE,
    PACKAGE_TABLES_DIR,
    SUMS_FILE,
    sha256_of,
)
from trustroute.core.validation import read_json
from trustroute.harness.live.attempts import utc_now
from trustroute.harness.study.config import LIVE_ENGINE
from trustroute.harness.study.export_inputs import PackagedInputs, config_text, export_inputs, inputs_readme
from trustroute.harness.study.inputs import INPUTS_DIR, config_sha256, relocated_config
from trustroute.participants.questionnaires import Questionnaire, questionnaire_plan

KEY_FILE = "export-key.json"
# the key file holds the only way back from the codes of every package shared: never rewritten unread
KEY_FIX = "restore it from a backup: it holds the key of every package exported from the study"
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


def row_participants(table: pa.Table, owners: dict[str, int] | None = None) -> list[int | None]:
    """Each row's participant number: its `participant`, else its `episode_id`'s, read from the id
    (`p<number>-`) or looked up in `owners` (episode id -> participant; None: neither)."""
    if "participant" in table.schema.names:
        return [int(p) for p in table.column("participant").to_pylist()]
    owners = owners or {}
    return [int(m.group(1)) if e and (m := EPISODE_PARTICIPANT.match(e)) else owners.get(e)
            for e in table.column("episode_id").to_pylist()]


def imported_episode_names(study_dir: Path) -> dict[str, tuple[int, str]]:
    """The episodes whose ids do not start `p<number>-` (an imported study's, `d04-t1-aware`, which
    name the driver): id -> (participant, the id's pseudonymous tail `<spec>-<condition>`)."""
    episodes = read_study_table(study_dir, "episodes", ["episode_id", "participant", "spec", "condition"])
    return {row["episode_id"]: (int(row["participant"]), f"{row['spec']}-{row['condition']}")
            for row in episodes.to_pylist() if not EPISODE_PARTICIPANT.match(row["episode_id"])}


def wall_clock_times(study_dir: Path, name: str, table: pa.Table) -> dict[str, list[datetime | None]]:
    """The wall-clock columns of `table`, the study's table `name`, as times; InputError naming the
    first row that is not an ISO 8601 date-time with its zone."""
    times: dict[str, list[datetime | None]] = {}
    for column in EXPORTED_TIMES.get(name, {}):
        times[column] = []
        for row, text in enumerate(table.column(column).to_pylist()):
            try:
                value = None if text is None else datetime.fromisoformat(text)
            except ValueError:
                value = None
            if text is not None and (value is None or value.tzinfo is None):
                raise InputError(str(Path(study_dir) / TABLES[name][0]), f"{column}, row {row}",
                                 f"not an ISO 8601 UTC date-time: {text!r}", REBUILD_FIX)
            times[column].append(value)
    return times


def first_times(timed: dict[str, pa.Table], times: dict[str, dict[str, list[datetime | None]]]
                ) -> dict[int, datetime]:
    """Each participant's first recorded wall-clock time over the study's tables that have wall-clock
    columns (`timed`, by name), whose `times` (`wall_clock_times`) are given."""
    first: dict[int, datetime] = {}
    for name, table in timed.items():
        numbers = row_participants(table)
        for values in times[name].values():
            for p, value in zip(numbers, values, strict=True):
                if p is not None and value is not None and (p not in first or value < first[p]):
                    first[p] = value
    return first


def exported_table(name: str, table: pa.Table, times: dict[str, list[datetime | None]],
                   key: dict[int, int], first: dict[int, datetime], people: bool,
                   imported: dict[str, tuple[int, str]] | None = None) -> pa.Table:
    """The study's table `name` (`table`, as read) as the package holds it (`exported_schema`):
    pseudonymised (`imported`: `imported_episode_names`), its wall-clock columns (`times`,
    `wall_clock_times`) as seconds since the participant's first time, its rows in pseudonym order,
    and (`people`: a live study) without the seeds that would give the participants' numbers back."""
    imported = imported or {}
    numbers = row_participants(table, {e: p for e, (p, _) in imported.items()})
    for column, values in times.items():
        seconds = [None if value is None or p is None else (value - first[p]).total_seconds()
                   for p, value in zip(numbers, values, strict=True)]
        index = table.schema.get_field_index(column)
        table = table.set_column(index, exported_schema(name).field(index), pa.array(seconds, pa.float64()))
    if people:
        table = table.drop_columns(list(WITHOUT_PEOPLE_SEEDS.get(name, ())))
    codes = np.array([-1 if p is None else key[p] for p in numbers], dtype=np.int64)
    order = np.lexsort((np.arange(len(codes)), codes))   # by code, then the table's own order
    return pseudonymised(table, key, imported).take(pa.array(order))


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


def pseudonymised(table: pa.Table, key: dict[int, int],
                  imported: dict[str, tuple[int, str]] | None = None) -> pa.Table:
    """`table` with its participant numbers and episode ids under the pseudonyms of `key`
    (`imported`: `imported_episode_names`, the ids that do not carry `p<number>-`)."""
    imported = imported or {}
    names = table.schema.names
    if "participant" in names:
        index = names.index("participant")
        values = [key[int(p)] for p in table.column(index).to_pylist()]
        table = table.set_column(index, table.schema.field(index), pa.array(values, pa.int64()))
    if "episode_id" in names:
        index = names.index("episode_id")
        ids = [renamed_episode(e, key, imported) for e in table.column(index).to_pylist()]
        table = table.set_column(index, table.schema.field(index), pa.array(ids, pa.string()))
    return table


def renamed_episode(episode: str | None, key: dict[int, int],
                    imported: dict[str, tuple[int, str]] | None = None) -> str | None:
    """The episode id under the pseudonyms of `key` (`imported`: `imported_episode_names`); an id
    that names no participant stays as it is. KeyError for a participant `key` has no code for."""
    imported = imported or {}
    if episode in imported:
        participant, tail = imported[episode]
        return f"p{key[participant]:05d}-{tail}"
    if episode is None or (match := EPISODE_PARTICIPANT.match(episode)) is None:
        return episode
    return f"p{key[int(match.group(1))]:05d}-{episode[match.end():]}"


def package_manifest(manifest: dict, config: dict, packaged: PackagedInputs, key: dict[int, int],
                     tables: list[str], out: Path) -> dict:
    """The package's manifest (PACKAGE_MANIFEST_FILE): the study manifest's keys, as far as they
    are neither personal nor the lab's (docs/dataset.md, "The manifest"): `config` is the package's
    (`study_config.json`'s), `inputs` records the package's copies in `out`, `files` its tables, a failed
    episode's id is pseudonymised (null for a participant with no data, who has no code) and its
    error left out (a traceback names the lab's files); when and how the study was run
    (`created_utc`, `command`) and the seeds (the `seed` column where the package gives them) are
    null."""
    failed = []
    for failure in manifest.get("failed_episodes") or []:
        try:
            episode = renamed_episode(failure.get("episode_id"), key)
        except KeyError:
            episode = None
        failed.append({"episode_id": episode, "error": None, "attempts": failure.get("attempts")})
    record = {path: {"sha256": sha256_of(Path(out) / path)} for path in packaged.roles}
    package = {
        **manifest, "config_path": PACKAGE_CONFIG_FILE, "config": config, "created_utc": None,
        "command": None, "failed_episodes": failed, "seeds": None,
        "files": {name: f"{PACKAGE_TABLES_DIR}/{TABLES[name][0]}" for name in tables},
        "inputs": {"dir": INPUTS_DIR, "files": record, "config_sha256": config_sha256(config)},
    }
    return {name: package[name] for name in MANIFEST_KEYS}


def export_study(study_dir: Path, out: Path, rng: np.random.Generator, ended: dict[str, int] | None,
                 registry: list[tuple[str, str]]) -> dict:
    """Write the package of `study_dir` into `out` (a new or empty directory); its index. `ended`: how
    many participants of a live study withdrew and how many declined the consent (harness/live/
    withdraw.py, `ended_counts`; None: a simulated study), for the README; `registry`: the labels and
    token digests of its participants (`registry_words`), which no copied input may hold."""
    study_dir, out = Path(study_dir), Path(out)
    manifest = read_manifest(study_dir)
    check_output_dir(out, "--out", "package directory")
    if out.exists() and any(out.iterdir()):
        raise InputError(str(out), "--out", "the directory is not empty", "pass a new or empty directory")
    if out.resolve().is_relative_to(study_dir.resolve()):
        raise InputError(str(out), "--out", "the package would be inside the study directory",
                         "pass a directory outside the study")
    shown = questionnaires_shown(manifest, study_dir)   # read before anything is written
    earlier = read_export_keys(study_dir)
    key = pseudonyms(participants_of(study_dir), rng)
    people = manifest.get("engine") == LIVE_ENGINE
    tables = [name for name, (file_name, _) in TABLES.items() if (study_dir / file_name).exists()]
    # the tables with wall-clock times (small), read once; every time checked before anything is written
    timed = {name: read_study_table(study_dir, name) for name in tables if name in EXPORTED_TIMES}
    times = {name: wall_clock_times(study_dir, name, table) for name, table in timed.items()}
    first = first_times(timed, times)
    imported = imported_episode_names(study_dir)
    (out / PACKAGE_TABLES_DIR).mkdir(parents=True, exist_ok=True)
    for name in tables:
        table = timed[name] if name in timed else read_study_table(study_dir, name)
        write_table(exported_table(name, table, times.get(name, {}), key, first, people, imported),
                    out / PACKAGE_TABLES_DIR / TABLES[name][0])
    book = {name: entries for name, entries in codebook(exported=True, people=people).items()
            if name in tables}
    atomic_write_text(out / "codebook.json", json.dumps(book, indent=1), "codebook")
    atomic_write_text(out / "codebook.md", codebook_markdown(book), "codebook")
    config = {setting: value for setting, value in manifest["config"].items()
              if not (people and setting in CONFIG_WITHOUT_PEOPLE_SEEDS)}
    packaged = export_inputs(study_dir, manifest, out, key, registry)
    package_config = config_text(config, packaged)
    atomic_write_text(out / PACKAGE_CONFIG_FILE, package_config, "study config")
    atomic_write_text(out / PACKAGE_MANIFEST_FILE,
                      json.dumps(package_manifest(manifest, json.loads(package_config), packaged, key, tables,
                                                  out), indent=1), "package manifest")
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
    atomic_write_text(out / "README.md", readme(manifest, tables, texts, len(key), ended, packaged), "README")
    write_export_keys(study_dir, earlier, out, key)
    files = sorted(path for path in out.rglob("*") if path.is_file())
    sums = "".join(f"{sha256_of(path)}  {path.relative_to(out)}\n" for path in files)
    atomic_write_text(out / SUMS_FILE, sums, "checksums")
    return {"tables": tables, "texts": texts, "inputs": list(packaged.roles),
            "inputs_left_out": packaged.left_out, "participants": len(key), "files": len(files) + 1}


def read_export_keys(study_dir: Path) -> list[dict]:
    """The packages exported from the study, as its key file holds them: [{"package": its resolved
    path, "written_utc": when (None for the single-package form's, which did not say), "pseudonyms":
    {"number": code}}], oldest first; [] before a first export. The single-package form, {"package",
    "pseudonyms"}, is read as one entry of the list form, {"packages": [...]}; InputError naming the
    place otherwise."""
    path = Path(study_dir) / KEY_FILE
    if not path.exists():
        return []
    key = read_json(path, "export key", fix=KEY_FIX)
    single = isinstance(key, dict) and "packages" not in key   # the form that held one package
    entries = [key] if single else key.get("packages") if isinstance(key, dict) else None
    if not isinstance(entries, list):
        raise InputError(str(path), "packages", "not an export key (a list of the packages exported)",
                         KEY_FIX)
    found = []
    for index, entry in enumerate(entries):
        place = "" if single else f"packages[{index}]."
        if not isinstance(entry, dict) or not isinstance(entry.get("package"), str):
            raise InputError(str(path), f"{place}package", "expected the package's path", KEY_FIX)
        codes, written = entry.get("pseudonyms"), entry.get("written_utc")
        if not isinstance(codes, dict) or any(isinstance(code, bool) or not isinstance(code, int)
                                               for code in codes.values()):
            raise InputError(str(path), f"{place}pseudonyms", "expected participant number -> code", KEY_FIX)
        if written is not None and not isinstance(written, str):
            raise InputError(str(path), f"{place}written_utc", "expected a UTC date-time", KEY_FIX)
        found.append({"package": entry["package"], "written_utc": written, "pseudonyms": codes})
    return found


def write_export_keys(study_dir: Path, earlier: list[dict], out: Path, key: dict[int, int]) -> None:
    """Write the study's key file: the `earlier` packages (`read_export_keys`) and the package `out`
    with its `key`, which replaces an earlier entry of the same path only where that entry's key is
    the same: a package written there before with another key may have been shared, moved or
    copied before the path was emptied for this one, and its key is the only way back from its codes."""
    package = str(Path(out).resolve())
    codes = {str(p): code for p, code in key.items()}
    entries = [entry for entry in earlier if (entry["package"], entry["pseudonyms"]) != (package, codes)]
    entries.append({"package": package, "written_utc": utc_now(), "pseudonyms": codes})
    atomic_write_text(Path(study_dir) / KEY_FILE, json.dumps({"packages": entries}, indent=1), "export key")


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


def participant_flow(manifest: dict, participants: int, ended: dict[str, int] | None) -> str:
    """The README's participant flow: planned (the study config's), with data in the package, and for
    a live study withdrawn, declined and the rest of the planned, who did not take part (counts: who
    is not said), so that the counts add up to the planned. An imported study planned none: its flow
    is who has data."""
    planned = (manifest.get("config") or {}).get("participants")
    flow = f"{participants} with data in this package"
    if planned is not None:
        flow = f"{planned} planned, {flow}"
    if ended is not None:
        flow += (f", {ended['withdrawn']} withdrawn (their data deleted before this export), "
                 f"{ended['declined']} declined consent (nothing of theirs was recorded)")
    if ended is not None and planned is not None:
        absent = planned - participants - ended["withdrawn"] - ended["declined"]
        flow += (f", {absent} did not take part (their link not opened, or nothing of theirs recorded "
                 "after it)")
    return f"Participants: {flow}."


def source_of(manifest: dict) -> list[str]:
    """The README's lines naming whose data an imported study's are, under what licence (the
    importer's attribution in the manifest); none for a study trustroute ran."""
    attribution = (manifest.get("real_study") or {}).get("attribution")
    if not attribution:
        return []
    return [f"Source: {attribution} The tables are derived from those logs by `trustroute import "
            "carla-logs`; cite the authors' paper and keep this attribution with the data.", ""]


def readme(manifest: dict, tables: list[str], texts: list[str], participants: int,
           ended: dict[str, int] | None, packaged: PackagedInputs) -> str:
    name = manifest.get("study", "the study")
    return "\n".join([
        f"# {name}: data package", "",
        f"A trustroute study ({manifest.get('engine')} engine), exported with `trustroute export`.", "",
        participant_flow(manifest, participants, ended), "",
        *source_of(manifest),
        "- `tables/`: the consolidated tables (Apache Parquet): " + ", ".join(tables) + ".",
        "- `codebook.md`, `codebook.json`: every column's type, whether it may be null, unit, meaning and "
        "allowed values.",
        "- `study_config.json`: the study's configuration; `versions.json`: the software that made it.",
        f"- `{PACKAGE_MANIFEST_FILE}`: the study's manifest (the keys of docs/dataset.md, \"The "
        "manifest\") as far as it is neither personal nor the lab's: the design (`config`), the planned, "
        "finished and failed episodes, each spec's and condition's certified policy values "
        "(`expected`); what the analysis reads beside the tables.",
        *inputs_readme(packaged),
        *(["- `texts/`: what participants were shown (" + ", ".join(texts) + ")"
           + (f"; `{QUESTIONNAIRES_TEXT}`: per placement (`before`, `after_each_trial`, `end`) each "
              "questionnaire as the station showed it (title, instructions, scale, items; an item's `id` "
              "is the `item` of the questionnaires table, `reversed` items are scored as min + max - value)"
              if QUESTIONNAIRES_TEXT in texts else "") + "."] if texts else []),
        "- `SHA256SUMS`: the SHA-256 of every other file (`sha256sum -c SHA256SUMS`).", "",
        "Participants are pseudonymous: each participant number is a random code (three digits; four "
        "above 900 participants, and so on), in the `participant` column and in every `episode_id`, "
        "written there with five digits (`p<code, 5 digits>-<spec>-<condition>`: code 114 is `p00114`). "
        "Missing values "
        "are nulls. Rows are in the order of the codes (a participant's rows in the study's order), not "
        "of enrolment, and times of day are not given: each wall-clock time is the seconds since the "
        "participant's first recorded one (`codebook.md`).", "",
        "To re-run the analysis: `trustroute analyze PACKAGE --json` (PACKAGE: this folder), which checks "
        "every file against `SHA256SUMS` and gives the study's own figures; add `--out DIR` for the "
        "report, written there (nothing is written into the package).", ""])
