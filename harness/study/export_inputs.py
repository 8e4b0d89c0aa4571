"""The inputs that define a study's task in its exported package (`trustroute export`): the specs
(formula, start road, atoms), the town and the SUMO net it drives, the driver model and
populations, the background routes, the policy files of the conditions and the policies the
study took from the policy cache, the questionnaire files and the study's config file: the
files the manifest records of the study's own `inputs/` (harness/study/inputs.py), copied under
the same relative paths, so that the package's `study_config.json` names them where they lie.
A study whose directory holds no copy of its inputs (one imported by `trustroute import
carla-logs`, or made before studies stored them) gets the files of its task as the installed
trustroute package ships them: its specs, town and driver model, found as its analysis finds them
(`task_files`), laid out as a study stores them (`content_folder`), with the package's
`study_config.json` naming them there.

Nothing is read from outside the study directory and the installed package: a recorded path that
leads out of `inputs/`, or a symbolic link there leading out of it (even to another file of the
study directory, such as its export key), is not followed, and a task file the package does not ship
is not read; either is left out. Nothing identifying enters the package: every text file is read
before it is copied (one that is not UTF-8, which the export cannot read, is left out; a policy's
decision table, the one binary input, is copied as it is). An absolute path in it is rewritten to
the package's copy of the file or folder it names (the manifest, or the task file's place in the
installed package, says where each copy came from), or, naming nothing the package holds, replaced
by `PATH_LEFT_OUT`; an episode id's participant number becomes its pseudonym. A file that, its paths
rewritten, still names the account that runs the export or its machine, a live participant's label
or token digest, a participant the package has no code for, or holds a token-shaped string is left
out. The README lists each file with its role, each file rewritten and each left out with the
reason.
"""

from __future__ import annotations

import getpass
import gzip
import hashlib
import json
import math
import os
import re
import socket
from dataclasses import dataclass, field
from pathlib import Path

from trustroute.core.output_files import atomic_write_bytes
from trustroute.core.packaged import SPECS, PackagedKind
from trustroute.core.wording import counted
from trustroute.harness.live.auth import TOKEN_BYTES
from trustroute.harness.study.inputs import (
    INPUTS_DIR,
    PATH_LEFT_OUT,
    POLICIES_DIR,
    Record,
    content_folder,
    task_files,
)
from trustroute.networks.town import TOWNS
from trustroute.participants.driver_model import DRIVER_MODELS
from trustroute.policies.routing.files import ZIP_MAGIC

# an absolute path: POSIX of two segments or more (not part of a URL, a fraction or a unit such as
# m/s), a file: URL, a Windows drive or network path, a path under a home folder (~/, ~name/)
ABSOLUTE_PATH = re.compile(
    r"file:///?[^\s\"'<>]*"
    r"|(?<![\w.:/~\\-])/(?:[\w.@+~-]+/)+[\w.@+~-]*"
    r"|\b[A-Za-z]:[\\/][^\s\"'<>]*"
    r"|\\\\[\w.-]+\\[^\s\"'<>]*"
    r"|(?<![\w/])~[\w.-]*/[^\s\"'<>]*")
EPISODE_NUMBER = re.compile(r"\bp(\d{5})-")
# a live participant's token (secrets.token_urlsafe): a run of URL-safe characters of its length
TOKEN = re.compile(rf"(?<![\w-])[\w-]{{{math.ceil(TOKEN_BYTES * 4 / 3)}}}(?![\w-])")
SHORTEST_NAME = 3   # an account or machine name shorter than this is a word of any file, not a name
ROLES = {"specs": "spec (formula, start road, atoms)", "town": "town", "driver_model": "driver model",
         "routes": "background routes (SUMO)", "robust_population": "driver population of the robust "
         "condition", "driver_population": "driver population of the synthetic drivers",
         "conditions": "policy file of a condition", "questionnaires": "questionnaire",
         "source_path": "the study's config file, as written"}
# the kind of packaged file each config key of `task_files` names
TASK_KINDS: dict[str, PackagedKind] = {"specs": SPECS, "town": TOWNS, "driver_model": DRIVER_MODELS}
NOT_SHIPPED = ("it is not a file the installed trustroute package ships, and the export reads nothing "
               "else outside the study directory")


@dataclass
class PackagedInputs:
    """The package's inputs: each copied file's role, the files rewritten (path -> what was
    rewritten) and those left out (path, or config place of a task file not shipped, -> why);
    `record`: each input's relative path -> {"sha256", "source"} (the manifest's, or for a study
    that stored none, `shipped_task`'s), `named`: the config values naming the copies of such a
    study's task files, `shipped`: whether the inputs are the installed package's files."""
    roles: dict[str, str] = field(default_factory=dict)
    rewritten: dict[str, str] = field(default_factory=dict)
    left_out: dict[str, str] = field(default_factory=dict)
    record: Record = field(default_factory=dict)
    named: dict[str, object] = field(default_factory=dict)
    shipped: bool = False

    @property
    def mapped(self) -> dict[str, str]:
        """The `path_map` of the full `record`, by which the copied files and the config are rewritten."""
        return path_map(self.record)


def input_roles(config: dict, recorded: list[str]) -> dict[str, str]:
    """The role of each recorded input (relative path): the config key that names it, else what a
    file stored beside the named ones is (a cached policy, a decision table, the town's net)."""
    roles: dict[str, str] = {}

    def named(key: str, value: object) -> None:
        if isinstance(value, str) and value in recorded:
            roles.setdefault(value, ROLES[key])
        elif isinstance(value, list | dict):
            for item in value.values() if isinstance(value, dict) else value:
                named(key, item)

    for key in ROLES:
        named(key, config.get(key))
    town = config.get("town")
    for path in recorded:
        if path in roles:
            continue
        if is_decision_table(path):
            roles[path] = "decision table of the policy file beside it"
        elif path.startswith(f"{POLICIES_DIR}/"):
            roles[path] = "policy the study took from the policy cache (an aware or robust condition)"
        elif isinstance(town, str) and Path(path).parts[:2] == Path(town).parts[:2]:
            roles[path] = "SUMO net the town drives"
        else:
            roles[path] = "input of the study"
    return roles


def path_map(record: dict[str, dict[str, str]]) -> dict[str, str]:
    """Absolute path on the lab's disk -> the package's relative path of its copy: each recorded
    file's source, and each source folder whose recorded files were all copied into one folder."""
    mapped = {entry["source"]: relative for relative, entry in record.items() if entry.get("source")}
    folders: dict[str, set[str]] = {}
    for source, relative in mapped.items():
        folders.setdefault(str(Path(source).parent), set()).add(Path(relative).parent.as_posix())
    mapped.update({folder: next(iter(copies)) for folder, copies in folders.items() if len(copies) == 1})
    return mapped


def rewritten_paths(text: str, mapped: dict[str, str]) -> tuple[str, int, int]:
    """`text` with every absolute path made the package's relative path of the file or folder it
    names (`path_map`), or `PATH_LEFT_OUT`; (text, paths made relative, paths left out). A path
    inside a copied folder naming no copy is left out too: rewritten into that folder it would name
    nothing the package holds, and carry the names of the lab's files."""
    counts = [0, 0]

    def relative(match: re.Match) -> str:
        path = match.group(0)
        named = path.rstrip("/") or path
        if named in mapped:
            counts[0] += 1
            return mapped[named] + path[len(named):]
        counts[1] += 1
        return PATH_LEFT_OUT

    return ABSOLUTE_PATH.sub(relative, text), counts[0], counts[1]


def identifying_names(registry: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """(name, what it is) of the words that identify the lab or a participant in a copied file: the
    account running the export and its machine, and `registry`'s, a live study's participant
    labels and token digests (harness/live/withdraw.py, `registry_words`)."""
    names = [(getpass.getuser(), "the user name of the account that runs the export"),
             (socket.gethostname(), "the machine's hostname"),
             (socket.gethostname().split(".")[0], "the machine's hostname"), *registry]
    return [(name, what) for name, what in names if len(name) >= SHORTEST_NAME]


def cleaned(text: str, mapped: dict[str, str], names: list[tuple[str, str]], key: dict[int, int]
            ) -> tuple[str, str | None, str | None]:
    """(the text as the package holds it, what was rewritten or None, why it is left out or None).
    Its absolute paths are rewritten before it is read for names: a path under the account's home
    folder is rewritten as any other, and what the package would hold is what is read."""
    text, relative, gone = rewritten_paths(text, mapped)
    for name, what in names:
        if re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", text):
            return text, None, f"it holds {what}"
    if TOKEN.search(text):
        return text, None, "it holds a string of the form of a participant's token"
    unknown = sorted({int(n) for n in EPISODE_NUMBER.findall(text)} - set(key))
    if unknown:
        return text, None, "it names a participant (an episode id) with no data in the package"
    text, ids = EPISODE_NUMBER.subn(lambda m: f"p{key[int(m.group(1))]:05d}-", text)
    said = [f"{counted(relative, 'absolute path')} made the package's relative paths of the copies "
            "they name"] * bool(relative) + [
        f"{counted(gone, 'absolute path')} naming nothing in the package replaced by `{PATH_LEFT_OUT}`"
    ] * bool(gone) + [f"{counted(ids, 'episode id')} pseudonymised"] * bool(ids)
    return text, "; ".join(said) or None, None


def within(study_dir: Path, relative: str) -> Path | None:
    """The stored input `relative` when it lies in the study's inputs/, as written and as a
    symbolic link leads (to another file of the study, such as its export key, as much as out of
    it); None otherwise (it is not followed)."""
    inputs = Path(study_dir).resolve() / INPUTS_DIR
    path = Path(study_dir) / relative
    if not Path(os.path.normpath(inputs.parent / relative)).is_relative_to(inputs):
        return None
    return path if path.resolve().is_relative_to(inputs) and path.is_file() else None


def shipped_task(manifest: dict, packaged: PackagedInputs, study_dir: Path) -> dict[str, Path]:
    """Fill `packaged` with the task files of a study that stored no copy of its inputs (`manifest`:
    its manifest), as the installed package ships them, each under the package's inputs/ as a
    study stores it; relative path -> the file to copy. A file the package does not ship is left
    out, under its config place, and its config value is kept. `study_dir`: the study, which an
    error names (`task_files`)."""
    config, packaged.shipped, sources = manifest.get("config") or {}, True, {}
    for key, paths in task_files(manifest, study_dir).items():
        values, many = [], isinstance(config.get(key), list)
        for index, path in enumerate(paths):
            if not TASK_KINDS[key].ships(path):
                packaged.left_out[f"config.{key}" + f"[{index}]" * many] = NOT_SHIPPED
                values.append(config[key][index] if many else config.get(key))
                continue
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            relative = f"{content_folder(digest)}/{path.name}"
            packaged.record[relative] = {"sha256": digest, "source": str(path)}
            sources[relative] = path
            values.append(relative)
        packaged.named[key] = values if many else values[0]
    return sources


def is_decision_table(relative: str) -> bool:
    """Whether a recorded input is a policy file's decision table (policies/routing/files.py)."""
    return relative.endswith(".npz")


def file_text(relative: str, data: bytes) -> str | None:
    """A copied file's text (a gzipped one's, decompressed), None for a binary file."""
    try:
        return (gzip.decompress(data) if relative.endswith(".gz") else data).decode()
    except (UnicodeDecodeError, OSError, EOFError):
        return None


def export_inputs(study_dir: Path, manifest: dict, out: Path, key: dict[int, int],
                  registry: list[tuple[str, str]]) -> PackagedInputs:
    """Copy the study's recorded inputs into the package `out` (see the module's doc); `key`: the
    pseudonyms, `registry`: the words of a live study's registry no file may hold (`identifying_names`)."""
    config, packaged = manifest.get("config") or {}, PackagedInputs()
    if manifest.get("inputs") is None:
        sources: dict[str, Path | None] = {**shipped_task(manifest, packaged, study_dir)}
    else:
        packaged.record = manifest["inputs"].get("files", {})
        sources = {relative: within(study_dir, relative) for relative in packaged.record}
    roles = input_roles({**config, **packaged.named}, list(packaged.record))
    mapped, names = packaged.mapped, identifying_names(registry)
    for relative in sorted(packaged.record):
        path = sources[relative]
        if path is None:
            packaged.left_out[relative] = ("it is not a file of the study's inputs/ (a path or a symbolic "
                                           "link leading out of inputs/ is not followed)")
            continue
        data = path.read_bytes()
        text = file_text(relative, data)
        why = None
        if text is None and not (is_decision_table(relative) and data.startswith(ZIP_MAGIC)):
            # a text file in another encoding is read no better than a binary one: not copied unread
            why = ("it is not UTF-8 text (nor a policy's decision table), so it cannot be read for "
                   "anything identifying")
        elif text is not None:
            kept, said, why = cleaned(text, mapped, names, key)
            if said is not None and relative.endswith(".gz"):
                why = f"{said}, which a gzipped file is not rewritten for"
            elif said is not None:
                data = kept.encode()
                packaged.rewritten[relative] = said
        if why is not None:
            packaged.left_out[relative] = why
            continue
        (out / relative).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(out / relative, data, "package input", "free disk space")
        packaged.roles[relative] = roles[relative]
    return packaged


def config_text(config: dict, packaged: PackagedInputs) -> str:
    """The package's `study_config.json`: the config, naming the copies of the task files of a study
    that stored none, any absolute path in it (a study made before its inputs were stored) made
    relative as in the copied files (by `packaged.mapped`)."""
    named = {**config, **packaged.named}
    return rewritten_paths(json.dumps(named, indent=1, default=str), packaged.mapped)[0]


def inputs_readme(packaged: PackagedInputs) -> list[str]:
    """The README's lines on the package's inputs."""
    if packaged.shipped:
        lines = ["- `inputs/`: the files that define the study's task, of which its directory holds no "
                 "copy (a study imported by `trustroute import carla-logs`, or made before studies stored "
                 "their inputs): the specs, town and driver model its config names (the packaged default "
                 "town and driver model where it names none), as the installed trustroute package ships "
                 "them and `trustroute analyze` reads them, under the paths `study_config.json` names them "
                 "by (`inputs/<first 16 hex of the file's SHA-256>/<file name>`):"]
    else:
        lines = ["- `inputs/`: the study's own copies of the files that define its task, under the paths "
                 "`study_config.json` names them by (`inputs/<first 16 hex of the SHA-256 the study "
                 "recorded>/<file name>`; policies from the policy cache in `inputs/policies/`):"]
    lines += [f"  - `{path}`: {role}" + (f"; rewritten for the package ({packaged.rewritten[path]}), so its "
                                           "SHA-256 differs from the one in its folder's name"
                                           if path in packaged.rewritten else "") + "."
              for path, role in packaged.roles.items()]
    lines += [f"  - `{path}`: left out, since {why}." for path, why in packaged.left_out.items()]
    return lines

