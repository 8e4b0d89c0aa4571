"""A study directory's own copy of its inputs, so it is analysed and replayed wherever it is copied.

At consolidation `store_inputs` copies into the study directory every file the config names: specs,
town (with the SUMO net of an imported town, where the town expects it) and driver model (the
packaged ones when the config names none), background route files, the populations
(`robust_population`, `[drivers] population`), a live study's questionnaire files, the policy files
among the conditions, the config file itself, and the "aware" and "robust" policies the study took
from the policy cache. Each file is stored by content hash, `inputs/<first 16 hex of its
SHA-256>/<its own file name>`: the name is kept because a spec's or a policy file's stem labels the
tables, and a policy file's decision table (`.npz`) lies beside it. A population whose types name
model files is stored with every model inline (its content hash, which the study's identity uses, is
the same). Cached policies go to `inputs/policies/` under their cache names, which are keys of their
inputs' content hashes, so a replay finds them there instead of synthesizing them again (a synthesis
cut by its time limit need not repeat exactly).

The manifest's `config` names the copies by paths relative to the study directory, and its
`inputs` lists each copy's path and SHA-256 with the file it was copied from (provenance, never
read), and the SHA-256 of the config itself (`config_sha256`). `relocated_config` turns the
manifest's config into absolute paths in the directory where the study lies; `verify_inputs`
checks every copy, and the manifest's config, against its recorded hash; `unchecked_config` is the
warning for a manifest that records no hash of its config.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path, PurePath, PureWindowsPath

from trustroute.core.dataset import CARLA_LOGS_ENGINE, MANIFEST_FILE
from trustroute.core.errors import InputError
from trustroute.core.output_files import atomic_write_bytes
from trustroute.core.package import (
    PACKAGE_MANIFEST_FILE,
    SHA256_HEX,
    SUMS_FILE,
    TAMPERED_FIX,
    is_package,
    sha256_of,
)
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.core.wording import counted
from trustroute.harness.study.config import NAMED_CONDITIONS
from trustroute.harness.study.context import (
    StudyContext,
    aware_horizon,
    aware_policy_path,
    belief_rule,
    robust_problem,
)
from trustroute.networks.town import load_town, town_file
from trustroute.participants.driver_model import driver_model_file
from trustroute.participants.driver_population import load_driver_population
from trustroute.participants.questionnaires import PACKAGED
from trustroute.policies.resolve import aware_cache_path, population_cache_path

INPUTS_DIR = "inputs"
POLICIES_DIR = f"{INPUTS_DIR}/policies"
MANIFEST_FIX = f"restore {MANIFEST_FILE} from the study directory's original copy"
# A config key of a study that stores no copy of its inputs (`trustroute import carla-logs` writes
# it): the SHA-256 of each of its specs, in the order of `specs`, by which `found_spec` knows a file
# for the one the study read, at its recorded path or, that path gone, the packaged spec of its name.
SPEC_SHA256 = "spec_sha256"
# What the export (export_inputs.py) writes, in a package's config and copied files, in place of an
# absolute path naming nothing the package holds: a spec so named is one the package does not hold.
PATH_LEFT_OUT = "<a path on the lab's disk, left out>"


# What a study directory holds of its inputs: relative path -> {"sha256": ..., "source": ...}.
Record = dict[str, dict[str, str]]


def content_folder(sha256: str) -> str:
    """The folder a study stores an input whose content has the SHA-256 `sha256` (hex) in, relative
    to the study directory: inputs/<its first 16 hex> (the export lays out a package's inputs by it
    too). The callers record the digest as well, so they hash the content once."""
    return f"{INPUTS_DIR}/{sha256[:16]}"


def _write(study_dir: Path, record: Record, data: bytes, name: str, source: str,
           folder: Path | None = None) -> str:
    """Store `data` as `name` in `folder` (default: its `content_folder`); its relative path."""
    digest = hashlib.sha256(data).hexdigest()
    folder = folder or study_dir / content_folder(digest)
    target = folder / name
    if not (target.is_file() and target.read_bytes() == data):
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(target, data, "study input copy", "free disk space in the study directory")
    relative = target.relative_to(study_dir).as_posix()
    record[relative] = {"sha256": digest, "source": source}
    return relative


def _store_file(study_dir: Path, record: Record, path: str | Path, folder: Path | None = None) -> str:
    """Store one file (and a policy file's decision table beside it); its relative path."""
    path = Path(path)
    relative = _write(study_dir, record, path.read_bytes(), path.name, str(path), folder)
    table = path.with_suffix(".npz")
    if path.suffix == ".json" and table.is_file():
        _write(study_dir, record, table.read_bytes(), table.name, str(table), (study_dir / relative).parent)
    return relative


def _store_town(study_dir: Path, record: Record, path: str | Path) -> str:
    """A town file, and the SUMO net an imported town drives where the town expects it (its
    `sumo_net.file`, relative to the town's folder)."""
    relative = _store_file(study_dir, record, path)
    town = load_town(path)
    net = town.sumo_net
    if net is not None and not Path(net.file).is_absolute():
        source = Path(path).parent / net.file
        folder = (study_dir / relative).parent / Path(net.file).parent
        _write(study_dir, record, source.read_bytes(), source.name, str(source), folder)
    return relative


def _store_population(study_dir: Path, record: Record, path: str) -> str:
    """A population file, with its models inline when its types name model files."""
    raw = json.loads(Path(path).read_text())
    if not any(isinstance(t, dict) and "model_file" in t for t in raw.get("types", [])):
        return _store_file(study_dir, record, path)

    text = json.dumps(load_driver_population(path).to_dict(), indent=2) + "\n"
    return _write(study_dir, record, text.encode(), Path(path).name, path)


def _cached_policies(context: StudyContext) -> list[Path]:
    """The policy-cache entries the study's "aware" and "robust" conditions were read from."""
    config = context.config
    paths = []
    for spec in context.specs.values():
        if "aware" in config.conditions:
            paths.append(aware_policy_path(context.town, context.nominal, spec, config))
        if "robust" in config.conditions and config.robust_population is not None:
            problem = robust_problem(context.town, spec, config)
            population = problem.population
            assert population is not None
            horizon, rule = aware_horizon(config), belief_rule(config)
            if population.n_types == 1:
                paths.append(aware_cache_path(context.town, problem.driver, problem.spec,
                                              config.policy_cache, horizon, rule))
            else:
                paths.append(population_cache_path(context.town, population, spec, config.robust_objective,
                                                   config.policy_cache, horizon, rule))
    return [p for p in paths if p.is_file()]


def store_inputs(study_dir: Path, context: StudyContext) -> tuple[dict, dict]:
    """Copy the inputs of the study (its context's) into `study_dir/inputs`; return (the config as
    the manifest records it, every path relative to the study directory; the `inputs` record)."""
    study_dir = Path(study_dir)
    config = context.config
    record: Record = {}
    recorded = json.loads(json.dumps(asdict(config), default=str))
    recorded["specs"] = [_store_file(study_dir, record, p) for p in config.specs]
    recorded["conditions"] = [c if c in NAMED_CONDITIONS else _store_file(study_dir, record, c)
                              for c in config.conditions]
    recorded["town"] = _store_town(study_dir, record, town_file(config.town))
    recorded["routes"] = [_store_file(study_dir, record, p) for p in config.routes]
    recorded["driver_model"] = _store_file(study_dir, record, driver_model_file(config.driver_model))
    for key in ("robust_population", "driver_population"):
        value = getattr(config, key)
        recorded[key] = None if value is None else _store_population(study_dir, record, value)
    for path in _cached_policies(context):
        _store_file(study_dir, record, path, study_dir / POLICIES_DIR)
    if config.questionnaires is not None:   # a live study's questionnaire files; packaged ones by name
        recorded["questionnaires"] = {
            placement: [entry if entry in PACKAGED else _store_file(study_dir, record, entry)
                        for entry in entries]
            for placement, entries in config.questionnaires.items()}
    recorded["policy_cache"] = POLICIES_DIR
    recorded["output"] = None   # the directory is wherever it is copied to
    if Path(config.source_path).is_file():
        recorded["source_path"] = _store_file(study_dir, record, config.source_path)
    return recorded, {"dir": INPUTS_DIR, "files": record, "config_sha256": config_sha256(recorded)}


def found_spec(config: dict, index: int) -> Path | None:
    """The spec file `config.specs[index]` of a manifest's config (as `relocated_config` gives it,
    its `SPEC_SHA256` checked by `spec_paths`): at its recorded absolute path (a relative one is
    never read from where the command runs), or that path gone or changed (a study that stores no
    copy of its inputs, moved to another machine), the packaged spec of its file name (that one
    first where it has the recorded SHA-256: the same bytes). A file is
    read only when it is provably the spec the study ran: where the config records the spec's
    SHA-256 the file has it, and the packaged spec stands in only then; with no SHA-256 recorded,
    the file at the recorded path is the study's own. None otherwise: a file edited since, or a
    packaged spec that merely shares its name (a user's edited file of that name), is not it."""
    recorded, digest = Path(config["specs"][index]), _recorded_spec_sha256(config, index)
    packaged = PACKAGED_SPECS / recorded_name(config["specs"][index])
    # the packaged copy first where it has the recorded SHA-256: the same bytes, and one that
    # `trustroute export` ships (a study imported by another install names that install's copy)
    if digest is not None and packaged.is_file() and sha256_of(packaged) == digest:
        return packaged
    if recorded.is_absolute() and recorded.is_file() and (digest is None or sha256_of(recorded) == digest):
        return recorded
    return None


def _on_windows(value: str) -> bool:
    """Whether a path a config records was written on Windows (a drive or a share, as a study
    imported there records it), not a path of this system's (where a backslash may be part of a
    file name)."""
    return bool(PureWindowsPath(value).drive) and not Path(value).is_absolute()


def recorded_name(value: str) -> str:
    """The file name of a path a config records, by the separators of the system it was written on
    (`_on_windows`)."""
    return PureWindowsPath(value).name if _on_windows(value) else Path(value).name


def recorded_stem(value: str) -> str:
    """`recorded_name` without its suffix: the name a spec's file gives it."""
    return PurePath(recorded_name(value)).stem


def _recorded_absolute(value: str) -> bool:
    return Path(value).is_absolute() or _on_windows(value)


def _recorded_spec_sha256(config: dict, index: int) -> str | None:
    hashes = config.get(SPEC_SHA256) or []
    return hashes[index] if index < len(hashes) else None


def _check_spec_sha256(config: dict, study_dir: Path, fix: str) -> None:
    """The config's `SPEC_SHA256` is absent, null or a list of SHA-256 digests (64 lowercase hex
    characters, or null for a spec with none), one per spec, or InputError naming the manifest and
    the key."""
    value, specs = config.get(SPEC_SHA256), config.get("specs") or []
    if value is None:
        return
    if not isinstance(value, list):
        wrong = f"it is {json.dumps(value)[:72]}"
    elif len(value) != len(specs):
        wrong = f"it has {counted(len(value), 'entry', 'entries')} for {counted(len(specs), 'spec')}"
    else:
        bad = [i for i, d in enumerate(value)
               if d is not None and not (isinstance(d, str) and SHA256_HEX.fullmatch(d))]
        if not bad:
            return
        wrong = f"its entry [{bad[0]}] is {json.dumps(value[bad[0]])[:72]}"
    shown = str(Path(study_dir) / manifest_wording(study_dir).manifest)
    raise InputError(shown, f"config.{SPEC_SHA256}", "not a list of the specs' SHA-256 (each 64 lowercase "
                     f"hex characters, or null), in the order of config.specs: {wrong}", fix)


def spec_paths(manifest: dict, study_dir: Path) -> list[Path]:
    """Every spec file of a manifest's config (`manifest`: as `load_study` gives it, its config as
    `relocated_config` gives it), each as `found_spec` finds it, of the study directory or package
    `study_dir`; a config's malformed `SPEC_SHA256`, checked before any spec is looked for, or a spec
    it finds none for, is an InputError naming the manifest, the key and the fix."""
    config = manifest.get("config") or {}
    shown = str(Path(study_dir) / manifest_wording(study_dir).manifest)
    if not isinstance(config.get("specs") or [], list):
        raise InputError(shown, "config.specs", "not a list of spec paths: "
                         f"{json.dumps(config['specs'])[:72]}", _spec_fix(manifest, study_dir))
    _check_spec_sha256(config, study_dir, _spec_fix(manifest, study_dir))
    for index, value in enumerate(config.get("specs") or []):
        if not isinstance(value, str) or "\0" in value:
            raise InputError(shown, f"config.specs[{index}]", f"not a spec's path: {json.dumps(value)[:72]}",
                             _spec_fix(manifest, study_dir))
    paths = []
    for index in range(len(config.get("specs") or [])):
        path = found_spec(config, index)
        if path is None:
            raise _unfound_spec(manifest, study_dir, index)
        paths.append(path)
    return paths


def not_stored_nor_absolute(what: str, value: str) -> str:
    """The problem of a config's input path that is never read: relative, yet not under inputs/
    (read from where the command runs, it could be any file)."""
    return (f"the study's {what} {value!r} is neither one of its stored inputs (inputs/...) nor an "
            "absolute path")


def _unfound_spec(manifest: dict, study_dir: Path, index: int) -> InputError:
    """The error of `spec_paths` for `config.specs[index]`, which `found_spec` finds no file for."""
    config = manifest["config"]
    value, digest = config["specs"][index], _recorded_spec_sha256(config, index)
    recorded, packaged = Path(value), PACKAGED_SPECS / recorded_name(value)
    shown, place = str(Path(study_dir) / manifest_wording(study_dir).manifest), f"config.specs[{index}]"
    differs = f"its SHA-256 differs from config.{SPEC_SHA256}[{index}]"
    if value == PATH_LEFT_OUT:
        problem = "the export left out this spec of the study (a file on the lab's disk), so the package "
        problem += "cannot be analysed again without it"
        fix = ("ask the study's authors for the spec, or analyse the study directory the package was "
               "exported from")
        return InputError(shown, place, problem, fix)
    absolute = _recorded_absolute(value)
    if not absolute:
        problem = not_stored_nor_absolute("spec", value)
    elif recorded.exists():
        problem = f"the study's spec {value} changed since the study was run ({differs})"
    else:
        problem = f"the study's spec {value} is gone"
    if packaged.is_file() and packaged != recorded:
        problem += (f", and the packaged {packaged.name} is not provably the spec the study ran (" +
                    ("the manifest records no SHA-256 of it" if digest is None else differs) + ")")
    return InputError(shown, place, problem, _spec_fix(manifest, study_dir, restore=absolute))


def _spec_fix(manifest: dict, study_dir: Path, restore: bool = False) -> str:
    """The fix of a config's spec that cannot be read (`restore`: at an absolute path, where the
    file the study ran can be put back; else the config is at fault, a relative path or a malformed
    `SPEC_SHA256`): a package's is to get it again. A study `trustroute import carla-logs` wrote
    (one imported before the import recorded its specs' SHA-256 among them) can be imported again,
    which writes its manifest anew."""
    said = manifest_wording(study_dir)
    if said is _PACKAGE_WORDING:
        return said.config_fix
    # the path is in the problem, not here: a fix is cut at 300 characters
    fix = (said.config_fix if not restore else
           "put the spec the study was run with back at that path, or analyse the study where it was made")
    if manifest.get("engine") != CARLA_LOGS_ENGINE:
        return fix
    return (f"{fix}, or import it again (`trustroute import carla-logs SOURCE --out DIR`), which records "
            "its specs' SHA-256")


def task_files(manifest: dict, study_dir: Path) -> dict[str, list[Path]]:
    """The files that define the task of the study in `study_dir` (`manifest`: its manifest, its
    config as `relocated_config` gives it), found as the analysis of a study directory loads them
    (analysis/study_directory.py, `study_inputs`): the specs by `spec_paths`, the town and the
    driver model the config names, else the packaged default ones (`town_file`,
    `driver_model_file`). Config key -> its files."""
    config = manifest.get("config") or {}
    return {"specs": spec_paths(manifest, study_dir),
            "town": [town_file(config.get("town"))],
            "driver_model": [driver_model_file(config.get("driver_model"))]}


def config_sha256(config: dict) -> str:
    """SHA-256 of the manifest's config (canonical JSON): its settings are no stored file, so the
    manifest records their hash beside the stored files' hashes."""
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()


def relocated_config(config: dict, study_dir: Path) -> dict:
    """The manifest's config with its stored inputs' paths (relative, under inputs/) made absolute
    in `study_dir`; other values, and the absolute paths of a study made before its inputs were
    stored, stay as they are. A path under inputs/ that leads out of the directory ("inputs/../..")
    is an InputError naming the manifest and the key."""
    said = manifest_wording(study_dir)
    shown = str(Path(study_dir) / said.manifest)
    study_dir = Path(study_dir).resolve()

    def place(key: str, value: object) -> object:
        if isinstance(value, str) and value.startswith(f"{INPUTS_DIR}/"):
            path = study_dir / value
            if not Path(os.path.normpath(path)).is_relative_to(study_dir / INPUTS_DIR):
                raise InputError(shown, f"config.{key}", f"{value!r} leads out of "
                                 "the study directory's stored inputs", said.config_fix)
            return str(path)
        if isinstance(value, list):
            return [place(key, v) for v in value]
        if isinstance(value, dict):   # [questionnaires]: placement -> entries
            return {k: place(f"{key}.{k}", v) for k, v in value.items()}
        return value

    return {key: place(key, value) for key, value in config.items()}


def unchecked_config(manifest: dict, study_dir: Path) -> str | None:
    """The warning line for a manifest that stored its inputs but no `inputs.config_sha256` (one
    written before config hashes were recorded): nothing checks its config, so an edit to it shows
    only as a replay that differs from the log. None when the hash is recorded, or when the manifest
    stored no inputs (its config is checked by `config_hash`, harness/study/replay.py). The replay
    says it, and so does every command reading a study (harness/commands/output.py,
    `study_warnings`)."""
    inputs = manifest.get("inputs")
    if not inputs or "config_sha256" in inputs:
        return None
    return (f"{Path(study_dir) / MANIFEST_FILE}: inputs.config_sha256: absent (the manifest predates config "
            "hashes), so its config is not checked: an edited config shows only as a replay that differs "
            "from the log")


@dataclass(frozen=True)
class _Wording:
    """What `verify_inputs` says of a study directory or of a package: the manifest's file, and each
    problem with its fix."""
    manifest: str
    missing: str
    missing_fix: str
    changed: str
    changed_fix: str
    config: str
    config_fix: str


_STUDY_WORDING = _Wording(
    MANIFEST_FILE, "a stored input of the study is missing",
    "copy the whole study directory, inputs/ included",
    "a stored input of the study changed since it was run (its SHA-256 differs from the manifest's)",
    "restore the study directory from its original copy", "since the study was run", MANIFEST_FIX)
_PACKAGE_WORDING = _Wording(
    PACKAGE_MANIFEST_FILE, f"an input the package's manifest records is missing from {SUMS_FILE}",
    TAMPERED_FIX, "an input the package's manifest records differs from its copy (its SHA-256 in "
    f"{SUMS_FILE} differs from the manifest's)", TAMPERED_FIX, "since the package was exported", TAMPERED_FIX)


def manifest_wording(study_dir: Path) -> _Wording:
    """What a message about the manifest of `study_dir` names: a package's own manifest
    (study_manifest.json, covered by its SHA256SUMS) and fix, or a study directory's."""
    return _PACKAGE_WORDING if is_package(study_dir) else _STUDY_WORDING


def verify_inputs(manifest: dict, study_dir: Path, checked: dict[str, str] | None = None) -> None:
    """Every stored input the manifest records is present with the hash it records, and so is the
    manifest's config (`inputs.config_sha256`), or InputError, worded for a study directory or a
    package as every message on its manifest is (`manifest_wording`). `checked`: the study is a
    package, and these are the SHA-256 of the files its SHA256SUMS lists, each verified
    (trustroute/core/package.py, `verify_package`): the recorded hashes are compared with them, so no
    file is hashed twice."""
    study_dir = Path(study_dir)
    said = manifest_wording(study_dir)
    for relative, entry in sorted((manifest.get("inputs") or {}).get("files", {}).items()):
        digest = _stored_sha256(study_dir, relative, checked)
        if digest is None:
            raise InputError(str(study_dir), relative, said.missing, said.missing_fix)
        if digest != entry.get("sha256"):
            raise InputError(str(study_dir), relative, said.changed, said.changed_fix)
    recorded = (manifest.get("inputs") or {}).get("config_sha256")
    if recorded is not None and config_sha256(manifest.get("config") or {}) != recorded:
        raise InputError(str(study_dir / said.manifest), "config", f"the manifest's config changed "
                         f"{said.config} (its SHA-256 differs from inputs.config_sha256)", said.config_fix)


def _stored_sha256(study_dir: Path, relative: str, checked: dict[str, str] | None) -> str | None:
    """The SHA-256 of the stored input `relative` (None: it is missing), as `verify_inputs` finds it:
    of the file in the study directory, or of a package, as its verified checksums give it."""
    if checked is not None:
        return checked.get(relative)
    path = study_dir / relative
    return sha256_of(path) if path.is_file() else None
