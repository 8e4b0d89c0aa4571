"""The inputs that define a study's task in its exported package (`trustroute export`): the specs
(formula, start road, atoms), the town and the SUMO net it drives, the driver model and
populations, the background routes, the policy files of the conditions and the policies the
study took from the policy cache, the questionnaire files and the study's config file: the
files the manifest records of the study's own `inputs/` (harness/study/inputs.py), copied under
the same relative paths, so that the package's `study_config.json` names them where they lie.

Nothing is read from outside the study directory: a recorded path that leads out of `inputs/`,
or through a symbolic link out of the study directory, is not followed, and the file is left
out. Nothing identifying enters the package: every text file is read before it is copied. An
absolute path in it is rewritten to the package's copy of the file or folder it names (the
manifest records where each copy came from), or, naming nothing the package holds, replaced by
`PATH_LEFT_OUT`; an episode id's participant number becomes its pseudonym. A file that names the
account that runs the export or its machine, a live participant's label or token digest, a
participant the package has no code for, or holds a token-shaped string is left out. The README
lists each file with its role, each file rewritten and each left out with the reason.
"""

from __future__ import annotations

import getpass
import gzip
import json
import math
import os
import re
import socket
from dataclasses import dataclass, field
from pathlib import Path

from trustroute.core.output_files import atomic_write_bytes
from trustroute.core.wording import counted
from trustroute.harness.live.auth import TOKEN_BYTES
from trustroute.harness.study.inputs import INPUTS_DIR, POLICIES_DIR

# what an absolute path naming nothing the package holds becomes in a copied file
PATH_LEFT_OUT = "<a path on the lab's disk, left out>"
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


@dataclass
class PackagedInputs:
    """The package's inputs: each copied file's role, the files rewritten (path -> what was
    rewritten) and those left out (path -> why)."""
    roles: dict[str, str] = field(default_factory=dict)
    rewritten: dict[str, str] = field(default_factory=dict)
    left_out: dict[str, str] = field(default_factory=dict)


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
        if path.endswith(".npz"):
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
    names (`path_map`), or `PATH_LEFT_OUT`; (text, paths made relative, paths left out)."""
    counts = [0, 0]

    def relative(match: re.Match) -> str:
        path = match.group(0)
        for source in sorted(mapped, key=len, reverse=True):
            if path == source or path.startswith(source.rstrip("/") + "/"):
                counts[0] += 1
                return mapped[source] + path[len(source.rstrip("/")):]
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
    """(the text as the package holds it, what was rewritten or None, why it is left out or None)."""
    for name, what in names:
        if re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", text):
            return text, None, f"it holds {what}"
    if TOKEN.search(text):
        return text, None, "it holds a string of the form of a participant's token"
    unknown = sorted({int(n) for n in EPISODE_NUMBER.findall(text)} - set(key))
    if unknown:
        return text, None, "it names a participant (an episode id) with no data in the package"
    text, relative, gone = rewritten_paths(text, mapped)
    text, ids = EPISODE_NUMBER.subn(lambda m: f"p{key[int(m.group(1))]:05d}-", text)
    said = [f"{counted(relative, 'absolute path')} made the package's relative paths of the copies "
            "they name"] * bool(relative) + [
        f"{counted(gone, 'absolute path')} naming nothing in the package replaced by `{PATH_LEFT_OUT}`"
    ] * bool(gone) + [f"{counted(ids, 'episode id')} pseudonymised"] * bool(ids)
    return text, "; ".join(said) or None, None


def within(study_dir: Path, relative: str) -> Path | None:
    """The stored input `relative` when it lies in the study's inputs/ without a symbolic link
    leading out of the study directory; None otherwise (it is not followed)."""
    root = Path(study_dir).resolve()
    path = Path(study_dir) / relative
    if not Path(os.path.normpath(root / relative)).is_relative_to(root / INPUTS_DIR):
        return None
    return path if path.resolve().is_relative_to(root) and path.is_file() else None


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
    record = (manifest.get("inputs") or {}).get("files", {})
    packaged = PackagedInputs()
    roles = input_roles(manifest.get("config") or {}, list(record))
    mapped, names = path_map(record), identifying_names(registry)
    for relative in sorted(record):
        path = within(study_dir, relative)
        if path is None:
            packaged.left_out[relative] = ("it is not a file of the study's inputs/ (a path or a symbolic "
                                           "link leading out of the study directory is not followed)")
            continue
        data = path.read_bytes()
        text = file_text(relative, data)
        why = None
        if text is not None:
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


def config_text(config: dict, manifest: dict) -> str:
    """The package's `study_config.json`: the config, any absolute path in it (a study made before
    its inputs were stored) made relative as in the copied files."""
    mapped = path_map((manifest.get("inputs") or {}).get("files", {}))
    return rewritten_paths(json.dumps(config, indent=1, default=str), mapped)[0]


def inputs_readme(packaged: PackagedInputs) -> list[str]:
    """The README's lines on the package's inputs."""
    if not packaged.roles and not packaged.left_out:
        return ["- `inputs/`: none; the study directory holds no copy of its inputs (a study made before "
                "studies stored them, or imported by `trustroute import carla-logs`, which stores none), so "
                "`study_config.json` names them as the study did, an absolute path replaced by "
                f"`{PATH_LEFT_OUT}`."]
    lines = ["- `inputs/`: the study's own copies of the files that define its task, under the paths "
             "`study_config.json` names them by (`inputs/<first 16 hex of the SHA-256 the study recorded>/"
             "<file name>`; policies from the policy cache in `inputs/policies/`):"]
    lines += [f"  - `{path}`: {role}" + (f"; rewritten for the package ({packaged.rewritten[path]}), so its "
                                           "SHA-256 differs from the one in its folder's name"
                                           if path in packaged.rewritten else "") + "."
              for path, role in packaged.roles.items()]
    lines += [f"  - `{path}`: left out, since {why}." for path, why in packaged.left_out.items()]
    return lines

