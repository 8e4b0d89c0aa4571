"""The study config: a TOML file read once into a frozen `StudyConfig`.

Minimal form (every other key is optional)::

    [study]
    participants = 21
    seed = 1
    engine = "sumo"            # or "model": the trust POMDP without SUMO
    specs = ["specs/phi1.toml", "specs/phi2.toml"]
    conditions = ["aware", "free"]   # or policy files

Optional `[study]` keys: `name`, `town`, `driver_model`, `horizon` (synthesis horizon of "aware"
policies, junctions; default 20), `fallback_after` (20; `false` disables the 20-junction rule),
`junction_cap` (60), `report_every` (1), `belief_rule` ("bayes" or "paper"), `output` (study directory),
`policy_cache` (where synthesized policies are cached), `background_vehicles` (SUMO engine:
seeded background traffic, vehicles kept on the net; default 0 = none, docs/scenes.md), `record`
(episode ids, e.g. `["p00000-phi1-aware"]`, written as Rerun recordings to
`<study dir>/recordings/<id>.rrd` while the study runs; SUMO engine only; not part of the content
hash, since it does not change the dataset), `robust_population` (the driver-population file the
"robust" condition's policy is synthesized for, docs/driver_types.md; required with that
condition) and `robust_objective` ("robust", the worst type's value, or "bayes", the prior-weighted
one; default "robust"). Optional `[population]` table: individual
variation of the drivers (participants.population.PopulationConfig; omitted: every driver is the
nominal model, reporting trust with accuracy 0.8). Optional `[drivers]` table: `population`, a
driver-population file (docs/driver_type_studies.md) from which each participant's true type is drawn; the
participant's model is that type's model (varied around it by `[population]` when given).

Every key, its default and its check: docs/formats/study_config.md.

Relative paths resolve against the config file's folder, then the current directory; spec names
also resolve against the packaged specs (`phi1`, `specs/phi1.toml`). Bad input raises InputError
naming the file, the key and the fix.
"""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.core.packaged import PACKAGED_SPECS, packaged_spec_names
from trustroute.core.validation import parse_toml, read_text
from trustroute.participants.driver_model import DEFAULT_REPORT_ACCURACY
from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER

DEFAULT_STUDIES_DIR = Path("studies")
ENGINES: tuple[str, ...] = ("sumo", "model", "live")  # "live": `trustroute live`, people in the loop
NAMED_CONDITIONS: tuple[str, ...] = ("aware", "free", "robust")
ROBUST_OBJECTIVES: tuple[str, ...] = ("robust", "bayes")
TABLES: tuple[str, ...] = ("study", "population", "drivers")
DRIVERS_KEYS: tuple[str, ...] = ("population",)
BELIEF_RULES: tuple[str, ...] = ("bayes", "paper")
STUDY_KEYS: tuple[str, ...] = (
    "participants",
    "seed",
    "engine",
    "specs",
    "conditions",
    "name",
    "town",
    "driver_model",
    "horizon",
    "fallback_after",
    "junction_cap",
    "report_every",
    "belief_rule",
    "output",
    "policy_cache",
    "background_vehicles",
    "record",
    "robust_population",
    "robust_objective",
)
# Upper limits checked before any work starts: a typo such as participants = 2**63 - 1 must be an
# error, not a plan that grows until memory runs out.
MAXIMUM: dict[str, int] = {
    "participants": 100_000,
    "seed": 2**63 - 1,
    "horizon": 1_000,
    "fallback_after": 10_000,
    "junction_cap": 10_000,
    "report_every": 10_000,
    "background_vehicles": 10_000,  # the tighter limit (what the roads hold) is checked below
}


@dataclass(frozen=True)
class StudyConfig:
    """A validated study. Paths are absolute; `population` is the raw [population] table or None."""

    source_path: str
    name: str
    participants: int
    seed: int
    engine: str
    specs: tuple[str, ...]  # absolute spec file paths
    conditions: tuple[str, ...]  # "aware", "free" or absolute policy file paths
    town: str | None = None
    driver_model: str | None = None
    horizon: int | None = None
    fallback_after: int | None = DEFAULT_FALLBACK_AFTER
    junction_cap: int = DEFAULT_JUNCTION_CAP
    report_every: int = 1
    belief_rule: str = "bayes"
    output: str | None = None
    policy_cache: str | None = None   # None: the resolver's default cache
    background_vehicles: int = 0      # SUMO engine: seeded background traffic (docs/scenes.md)
    record: tuple[str, ...] = ()      # episode ids recorded to Rerun during the run
    population: dict | None = None   # compared by value; hashed through its canonical JSON (__hash__)
    robust_population: str | None = None   # the "robust" condition's population file (absolute)
    robust_objective: str = "robust"       # its objective: "robust" (worst type) or "bayes"
    driver_population: str | None = None  # [drivers] population: absolute path of the population file

    def __hash__(self) -> int:
        # Every field, [population] included: configs that differ only there must never share a
        # cached study context (harness/study/context.py). The dict is hashed as canonical JSON.
        values = tuple(getattr(self, f.name) for f in fields(self) if f.name != "population")
        return hash((values, json.dumps(self.population, sort_keys=True, default=str)))

    @property
    def condition_names(self) -> tuple[str, ...]:
        """Short labels: "aware", "free", "robust", or a policy file's stem."""
        return tuple(condition_label(c) for c in self.conditions)

    @property
    def spec_names(self) -> tuple[str, ...]:
        return tuple(Path(s).stem for s in self.specs)

    @property
    def report_accuracy(self) -> float:
        value = (self.population or {}).get("report_accuracy", DEFAULT_REPORT_ACCURACY)
        return float(value)

    def to_dict(self) -> dict:
        return asdict(self)

    @functools.cached_property
    def content_hash(self) -> str:
        """SHA-256 of what determines the dataset: every setting (not the file's formatting or its
        location, nor the output directory) plus the content of the spec, town, model and policy
        files it names."""
        settings = {k: v for k, v in asdict(self).items()
                    if k not in ("source_path", "output", "name", "record")}
        if settings["robust_population"] is None:
            # a study without the robust condition keeps its earlier hash
            del settings["robust_population"], settings["robust_objective"]
        if settings["driver_population"] is None:
            del settings["driver_population"]  # a study without [drivers] keeps its earlier hash
        digest = hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode())
        for path in (*self.specs, self.town, self.driver_model, *self.conditions):
            if path and Path(path).is_file():
                digest.update(Path(path).read_bytes())
        if self.robust_population is not None:
            from trustroute.participants.driver_population import load_driver_population

            digest.update(load_driver_population(self.robust_population).content_hash.encode())
        if self.driver_population is not None:
            # the population's content hash covers the model files its types name
            from trustroute.participants.driver_population import load_driver_population

            digest.update(load_driver_population(self.driver_population).content_hash.encode())
        return digest.hexdigest()

    def with_overrides(self, **changes: object) -> StudyConfig:
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


def condition_label(condition: str) -> str:
    return condition if condition in NAMED_CONDITIONS else Path(condition).stem


def _resolve_path(value: str, base: Path, source: str, key: str, what: str, fix: str) -> Path:
    """Config folder first, then the current directory."""
    candidates = [Path(value)] if Path(value).is_absolute() else [base / value, Path.cwd() / value]
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    raise InputError(source, key, f"{what} {value!r} not found (looked in {base} and {Path.cwd()})", fix)


def _resolve_spec(value: str, base: Path, source: str, key: str) -> Path:
    """A spec file: relative to the config, the current directory, or a packaged spec by name."""
    candidates = [Path(value)] if Path(value).is_absolute() else [base / value, Path.cwd() / value]
    name = Path(value).name
    candidates.append(PACKAGED_SPECS / name)
    if not name.endswith(".toml"):
        candidates.append(PACKAGED_SPECS / f"{name}.toml")
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    packaged = packaged_spec_names()
    shipped = f" or a packaged spec ({', '.join(packaged)})" if packaged else ""
    raise InputError(
        source,
        key,
        f"spec {value!r} not found (looked in {base}, {Path.cwd()} and the packaged specs)",
        f"give the path of an existing spec file{shipped}",
    )


def _integer(
    study: dict, key: str, source: str, minimum: int, default: int | None = None, fix: str = ""
) -> int | None:
    if key not in study:
        return default
    value = study[key]
    maximum = MAXIMUM[key]
    if isinstance(value, bool) or not isinstance(value, int) or not minimum <= value <= maximum:
        raise InputError(
            source,
            f"study.{key}",
            f"expected an integer from {minimum} to {maximum}, got {str(value)[:40]}",
            fix or f"write e.g. {key} = {max(minimum, 1)}",
        )
    return value


def _string_list(study: dict, key: str, source: str, fix: str) -> list[str]:
    if key not in study:
        raise InputError(source, f"study.{key}", f"missing key '{key}'", fix)
    value = study[key]
    if not (isinstance(value, list) and value and all(isinstance(v, str) and v for v in value)):
        raise InputError(source, f"study.{key}", f"expected a non-empty list of strings, got {value!r}", fix)
    if len(set(value)) != len(value):
        raise InputError(source, f"study.{key}", "lists the same entry twice", "list each entry once")
    return value


def _population(table: object, source: str) -> dict | None:
    """The raw [population] table, validated by participants.population."""
    if table is None:
        return None
    from trustroute.participants.population import population_config_from_dict

    population_config_from_dict(table, source)  # raises InputError naming the key
    return dict(table)


def _driver_population(table: object, base: Path, source: str) -> str | None:
    """The [drivers] table: the driver-population file, resolved and read (InputError if bad)."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise InputError(source, "drivers", "expected a table", 'write [drivers] population = "FILE"')
    unknown = sorted(set(table) - set(DRIVERS_KEYS))
    if unknown:
        raise InputError(source, f"drivers.{unknown[0]}", f"unknown key '{unknown[0]}'",
                         f"use only {', '.join(DRIVERS_KEYS)}")
    value = table.get("population")
    fix = ("give the path of a driver-population file (docs/driver_type_studies.md), "
           "e.g. population = \"types.json\"")
    if not isinstance(value, str) or not value:
        raise InputError(source, "drivers.population", f"expected a file path, got {value!r}", fix)
    path = _resolve_path(value, base, source, "drivers.population", "driver-population file", fix)
    from trustroute.participants.driver_population import load_driver_population

    load_driver_population(path)  # raises InputError naming the file and the place
    return str(path)


def study_config_from_dict(data: object, source: str = "<study>", base: Path | None = None) -> StudyConfig:
    """Validate a parsed study document; relative paths resolve against `base`, then the cwd."""
    base = base if base is not None else Path.cwd()
    if not isinstance(data, dict):
        raise InputError(source, "top level", "expected a TOML table", "start with a [study] table")
    unknown_tables = sorted(set(data) - set(TABLES))
    if unknown_tables:
        raise InputError(
            source,
            unknown_tables[0],
            f"unknown table or key '{unknown_tables[0]}'",
            f"use only {', '.join(f'[{t}]' for t in TABLES)}",
        )
    study = data.get("study")
    if not isinstance(study, dict):
        raise InputError(
            source,
            "study",
            "missing [study] table",
            "add [study] with participants, seed, engine, specs and conditions",
        )
    unknown = sorted(set(study) - set(STUDY_KEYS))
    if unknown:
        raise InputError(
            source, f"study.{unknown[0]}", f"unknown key '{unknown[0]}'", f"use only {', '.join(STUDY_KEYS)}"
        )
    for key in ("participants", "seed"):
        if key not in study:
            raise InputError(
                source,
                f"study.{key}",
                f"missing key '{key}'",
                f"add {key} = 21" if key == "participants" else "add seed = 1",
            )
    participants = _integer(
        study, "participants", source, 1, fix="write the number of participants, e.g. participants = 21"
    )
    seed = _integer(study, "seed", source, 0, fix="write a non-negative integer, e.g. seed = 1")
    engine = study.get("engine", "sumo")
    if engine not in ENGINES:
        raise InputError(
            source,
            "study.engine",
            f"unknown engine {engine!r}",
            f"use one of {', '.join(repr(e) for e in ENGINES)}",
        )
    spec_values = _string_list(study, "specs", source, 'write specs = ["specs/phi1.toml", "specs/phi2.toml"]')
    specs = tuple(str(_resolve_spec(v, base, source, "study.specs")) for v in spec_values)
    if len({Path(s).stem for s in specs}) != len(specs):
        raise InputError(
            source,
            "study.specs",
            "two specs share a file name",
            "give every spec file a distinct name (the name labels the tables)",
        )
    condition_values = _string_list(study, "conditions", source, 'write conditions = ["aware", "free"]')
    conditions = []
    for value in condition_values:
        if value in NAMED_CONDITIONS:
            conditions.append(value)
        else:
            conditions.append(
                str(
                    _resolve_path(
                        value,
                        base,
                        source,
                        "study.conditions",
                        "policy file",
                        'use "aware", "free", "robust" or a policy file written by trustroute synth',
                    )
                )
            )
    if len({condition_label(c) for c in conditions}) != len(conditions):
        raise InputError(
            source, "study.conditions", "two conditions share a name", "give policy files distinct names"
        )

    def optional_file(key: str, what: str, fix: str) -> str | None:
        if key not in study:
            return None
        if not isinstance(study[key], str) or not study[key]:
            raise InputError(source, f"study.{key}", f"expected a file path, got {study[key]!r}", fix)
        return str(_resolve_path(study[key], base, source, f"study.{key}", what, fix))

    town = optional_file("town", "town file", "give an existing town file or omit town (the default)")
    driver_model = optional_file(
        "driver_model",
        "driver model file",
        "give an existing driver model file or omit driver_model (the default)",
    )
    horizon = _integer(
        study, "horizon", source, 1,
        fix=f"write a positive number of junctions or omit horizon ({DEFAULT_FALLBACK_AFTER})",
    )
    fallback_value = study.get("fallback_after", DEFAULT_FALLBACK_AFTER)
    if fallback_value is False:
        fallback_after = None
    else:
        fallback_after = _integer(
            study,
            "fallback_after",
            source,
            0,
            default=DEFAULT_FALLBACK_AFTER,
            fix=f"write fallback_after = {DEFAULT_FALLBACK_AFTER}, or false to disable the rule",
        )
    junction_cap = _integer(study, "junction_cap", source, 1, default=DEFAULT_JUNCTION_CAP)
    background_vehicles = _integer(
        study, "background_vehicles", source, 0, default=0,
        fix="write background_vehicles = 20 (vehicles kept on the net), or 0 / omit it for none",
    )
    if background_vehicles > 200:
        raise InputError(source, "study.background_vehicles", f"{background_vehicles} vehicles is more than "
                         "the town's roads hold (at most 200)", "write a number from 0 to 200")
    report_every = _integer(study, "report_every", source, 1, default=1)
    belief_rule = study.get("belief_rule", "bayes")
    if belief_rule not in BELIEF_RULES:
        raise InputError(
            source, "study.belief_rule", f"unknown belief rule {belief_rule!r}", "use 'bayes' or 'paper'"
        )
    name = study.get("name", Path(source).stem if source.endswith(".toml") else "study")
    if not isinstance(name, str) or not name:
        raise InputError(
            source, "study.name", f"expected a non-empty string, got {name!r}", 'write name = "paper"'
        )
    output = None
    if "output" in study:
        if not isinstance(study["output"], str) or not study["output"]:
            raise InputError(
                source,
                "study.output",
                f"expected a directory path, got {study['output']!r}",
                'write output = "out/paper"',
            )
        output = str((base / study["output"]).resolve())
    policy_cache = None
    if "policy_cache" in study:
        if not isinstance(study["policy_cache"], str) or not study["policy_cache"]:
            raise InputError(
                source,
                "study.policy_cache",
                "expected a directory path",
                'write policy_cache = "cache/policies" or omit it',
            )
        policy_cache = str((base / study["policy_cache"]).resolve())
    record = tuple(_string_list(study, "record", source, 'write record = ["p00000-phi1-aware"]')
                   if "record" in study else ())
    robust_population = optional_file(
        "robust_population", "driver-population file",
        "give the driver-population file the robust policy is made for (docs/driver_types.md)")
    if robust_population is not None:
        from trustroute.participants.driver_population import load_driver_population

        load_driver_population(robust_population)  # raises InputError naming the file and the place
    if "robust" in conditions and robust_population is None:
        raise InputError(source, "study.robust_population", "the 'robust' condition needs the driver "
                         "population its policy is made for",
                         'add robust_population = "types.json" to [study] (docs/driver_types.md)')
    robust_objective = study.get("robust_objective", "robust")
    if robust_objective not in ROBUST_OBJECTIVES:
        raise InputError(source, "study.robust_objective",
                         f"unknown objective {str(robust_objective)[:40]!r}",
                         "use 'robust' (the worst type's value) or 'bayes' (the prior-weighted value)")
    return StudyConfig(
        source_path=source,
        name=name,
        participants=participants,
        seed=seed,
        engine=engine,
        specs=specs,
        conditions=tuple(conditions),
        town=town,
        driver_model=driver_model,
        horizon=horizon,
        fallback_after=fallback_after,
        junction_cap=junction_cap,
        report_every=report_every,
        belief_rule=belief_rule,
        output=output,
        policy_cache=policy_cache,
        background_vehicles=background_vehicles,
        record=record,
        population=_population(data.get("population"), source),
        robust_population=robust_population,
        robust_objective=robust_objective,
        driver_population=_driver_population(data.get("drivers"), base, source),
    )


def load_study_config(path: str | Path) -> StudyConfig:
    """Read and validate a study config file, or raise InputError."""
    shown = str(path)
    text = read_text(path, shown, "the study config",
                     "pass an existing TOML file (see harness/study/examples/)")
    data = parse_toml(text, shown, "study config")
    return study_config_from_dict(data, shown, Path(path).resolve().parent)


def study_directory(config: StudyConfig, out: str | None) -> Path:
    """Where a study is written: `out`, else the config's output, else studies/<name>."""
    if out is not None:
        return Path(out)
    if config.output is not None:
        return Path(config.output)
    return DEFAULT_STUDIES_DIR / config.name
