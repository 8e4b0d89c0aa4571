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
seeded background traffic, vehicles kept on the net, on an imported town trips per minute from
randomTrips.py; default 0 = none, docs/scenes.md), `routes`
(SUMO engine: SUMO route files of background traffic, e.g. the scenario's own demand), `record`
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
Optional `[live]` table (engine "live"): `view`, what the participant station shows, "driver"
(the first-person driver's view, the default) or "map" (the top-down view alone); `driving`, how a
person in control drives, "assisted" (pedal keys and a pull-out to pass, the default) or
"continuous" (steering wheel and pedals, or their keyboard stand-ins).

Every key, its default and its check: docs/formats/study_config.md.

Relative paths resolve against the config file's folder, then the current directory, then the
packaged files by name (trustroute/core/packaged.py: specs `phi1`, also `specs/phi1.toml`; towns
`town01_carla`, `pentagon`, `city`; routes `city`; driver models and populations by file stem). Bad
input raises InputError naming the file, the key and the fix.
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Literal, TypedDict, get_args

from trustroute.core import defaults, ranges
from trustroute.core.errors import InputError
from trustroute.core.fields import (
    Field,
    Integer,
    ListOf,
    OneOf,
    Seen,
    Table,
    Text,
    check_fields,
    check_value,
    field_table,
    keys,
)
from trustroute.core.package import outside_packages
from trustroute.core.packaged import SPECS, PackagedKind
from trustroute.core.validation import FILE_NAME, FILE_NAME_RULE, PATH_TEXT, parse_toml, read_text
from trustroute.core.wording import shown_value
from trustroute.networks.cities import ROUTES, check_route_set_town, read_route_file, route_set_town
from trustroute.networks.town import TOWNS, load_town
from trustroute.participants.driver_model import DEFAULT_REPORT_ACCURACY, DRIVER_MODELS
from trustroute.participants.driver_population import POPULATIONS, load_driver_population
from trustroute.participants.population import population_table
from trustroute.participants.questionnaires import resolved_table
from trustroute.policies.model.trust_pomdp import BELIEF_RULE_NAMES, BeliefRule
from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP, JUNCTION_CAPS
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER

DEFAULT_STUDIES_DIR = Path("studies")
LIVE_ENGINE = "live"   # `trustroute live`: people in the loop
ENGINES: tuple[str, ...] = ("sumo", "model", LIVE_ENGINE)
ENGINE_NAMES = OneOf(choices=ENGINES, noun="engine")   # the config's `engine` and its override
ENGINE_FIX = f"use one of {', '.join(repr(e) for e in ENGINES)}"
NAMED_CONDITIONS: tuple[str, ...] = ("aware", "free", "robust")
LIVE_VIEWS: tuple[str, ...] = ("driver", "map")   # [live] view: the participant station's view
LIVE_DRIVING: tuple[str, ...] = ("assisted", "continuous")   # [live] driving: how a person drives
# [live] inputs: what a participant may drive with in continuous driving (all, unless the study
# says otherwise): a steering wheel with pedals, a gamepad, the keyboard (harness/live/pages/inputs.js)
LiveInput = Literal["wheel", "gamepad", "keyboard"]
LIVE_INPUTS: tuple[str, ...] = get_args(LiveInput)
ROBUST_OBJECTIVES: tuple[str, ...] = ("robust", "bayes")
# the belief sources a study's specs are evaluated on (analysis/belief_sources.py says what each is)
BELIEF_SOURCES: tuple[str, ...] = ("filter", "reported", "reference", "true")


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
    belief_rule: BeliefRule = "bayes"
    output: str | None = None
    policy_cache: str | None = None   # None: the resolver's default cache (also for one in a package)
    background_vehicles: int = 0      # SUMO engine: seeded background traffic (docs/scenes.md)
    routes: tuple[str, ...] = ()      # SUMO engine: route files of background traffic (absolute)
    record: tuple[str, ...] = ()      # episode ids recorded to Rerun during the run
    population: dict | None = None   # compared by value; hashed through its canonical JSON (__hash__)
    robust_population: str | None = None   # the "robust" condition's population file (absolute)
    robust_objective: str = "robust"       # its objective: "robust" (worst type) or "bayes"
    driver_population: str | None = None  # [drivers] population: absolute path of the population file
    questionnaires: dict | None = None    # [questionnaires] (live): placement -> names or absolute files
    live_view: str = "driver"               # [live] view: the participant station's view
    live_driving: str = "assisted"          # [live] driving: pedals and pull-out, or wheel and pedals
    live_inputs: tuple[str, ...] = LIVE_INPUTS   # [live] inputs: the inputs continuous driving allows
    # the pre-registered primary belief source of the analysis (None: the neutral default,
    # analysis/belief_sources.py `default_belief_source`)
    belief_source: str | None = None

    def __hash__(self) -> int:
        # Every field, [population] included: configs that differ only there hash apart, equal
        # configs hash alike (the generated hash would fail on the dicts, hashed as canonical JSON).
        raw = ("population", "questionnaires")
        values = tuple(getattr(self, f.name) for f in fields(self) if f.name not in raw)
        return hash((values, json.dumps([self.population, self.questionnaires], sort_keys=True, default=str)))

    @property
    def condition_names(self) -> tuple[str, ...]:
        """Short labels: "aware", "free", "robust", or a policy file's stem."""
        return tuple(condition_label(c) for c in self.conditions)

    @property
    def spec_names(self) -> tuple[str, ...]:
        return tuple(Path(s).stem for s in self.specs)

    @property
    def report_accuracy(self) -> float:
        return float((self.population or {}).get("report_accuracy", DEFAULT_REPORT_ACCURACY))

    def to_dict(self) -> dict:
        return asdict(self)

    @functools.cached_property
    def content_hash(self) -> str:
        """SHA-256 of what determines the dataset: every setting, each file it names as its name and
        content, each population as its content hash; not the config's formatting, nor where its
        files are (a copied project, another checkout), the output directory or the policy cache."""
        settings = {k: v for k, v in asdict(self).items()
                    if k not in ("source_path", "output", "name", "record", "policy_cache")}
        for key, default in _UNSET.items():
            if settings[key] == default:
                del settings[key]  # a setting left at its default hashes as a config without its key
        if "robust_population" not in settings:
            del settings["robust_objective"]  # a study without the robust condition hashes without it
        for key in ("specs", "conditions", "routes"):
            if key in settings:
                settings[key] = [_file_identity(entry) for entry in settings[key]]
        for key in ("town", "driver_model"):
            settings[key] = None if settings[key] is None else _file_identity(settings[key])
        for key in ("robust_population", "driver_population"):
            if key in settings:
                # the population's content hash covers the model files its types name
                settings[key] = load_driver_population(settings[key]).content_hash
        if "questionnaires" in settings:
            settings["questionnaires"] = {placement: [_file_identity(entry) for entry in entries]
                                          for placement, entries in settings["questionnaires"].items()}
        return hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode()).hexdigest()

    def with_overrides(self, *, engine: str | None = None) -> StudyConfig:
        """A copy with `engine` replaced when given, checked by the config key's rule (InputError)."""
        if engine is None:
            return replace(self)
        return replace(self, engine=check_value(engine, ENGINE_NAMES, "engine", "", fix=ENGINE_FIX))


# The settings a config may leave out, at their defaults: hashed only when set otherwise.
_UNSET: dict[str, object] = {"robust_population": None, "driver_population": None, "questionnaires": None,
                             "routes": (), "live_view": "driver", "live_driving": "assisted",
                             "live_inputs": LIVE_INPUTS, "belief_source": None}


def _file_identity(entry: str) -> str | dict[str, str]:
    """A config's entry as its hash sees it: a file (the config keeps them absolute) as its name and
    the SHA-256 of its bytes, anything else (a named condition, a packaged questionnaire) as is."""
    path = Path(entry)
    if not (path.is_absolute() and path.is_file()):
        return entry
    return {"file": path.name, "sha256": hashlib.sha256(path.read_bytes()).hexdigest()}


def condition_label(condition: str) -> str:
    return condition if condition in NAMED_CONDITIONS else Path(condition).stem


def _folders(value: str, base: Path) -> list[Path]:
    """Where a relative path is looked for: the config's folder, then the current directory (an
    absolute path is looked for nowhere else)."""
    return [] if Path(value).is_absolute() else [base, Path.cwd()]


def _found(value: str, base: Path) -> Path | None:
    """The file `value` names, looked for in `_folders` (or as it is, when absolute)."""
    candidates = [folder / value for folder in _folders(value, base)] or [Path(value)]
    return next((candidate.resolve() for candidate in candidates if candidate.is_file()), None)


def _looked_in(value: str, base: Path, *more: str) -> str:
    """' (looked in A, B and C)': `_folders` (once when they are one), then `more`."""
    places = [*map(str, dict.fromkeys(folder.resolve() for folder in _folders(value, base))), *more]
    return f" (looked in {', '.join(places[:-1])} and {places[-1]})" if len(places) > 1 else (
        f" (looked in {places[0]})" if places else "")


def _resolve_path(value: str, base: Path, source: str, key: str, what: str, fix: str,
                  packaged: PackagedKind | None = None) -> Path:
    """Config folder first, then the current directory, then a packaged file of that name."""
    found = _found(value, base) or (packaged.path(value) if packaged is not None else None)
    if found is not None:
        return found.resolve()
    names = f" or a packaged name ({', '.join(packaged.names())})" if packaged is not None else ""
    raise InputError(source, key, f"{what} {value!r} not found{_looked_in(value, base)}",
                     fix + names)


def _resolve_spec(value: str, base: Path, source: str, key: str) -> Path:
    """A spec file: relative to the config, the current directory, or a packaged spec by name
    (a path's file name too: "specs/phi1.toml" is the packaged phi1 where that path is missing)."""
    found = _found(value, base) or SPECS.path(Path(value).name)
    if found is not None:
        return found.resolve()
    raise InputError(
        source,
        key,
        f"spec {value!r} not found{_looked_in(value, base, 'the packaged specs')}",
        SPECS.fix(),
    )


def _towns() -> PackagedKind:
    return TOWNS


def _routes() -> PackagedKind:
    return ROUTES


def _route_files(values: Sequence[str], town: str | None, base: Path, source: str) -> tuple[str, ...]:
    """The background route files, resolved and each parsed once (networks/cities.py
    `read_route_file`, as the episodes read them): a file SUMO cannot load is refused before any
    study directory is made, not in every episode; a packaged route set only with its own town
    (`town`: the study's town file, None the default)."""
    routes = tuple(_resolve_path(value, base, source, "study.routes", "SUMO route file", FILE_FIX["routes"],
                                 _routes()) for value in values)
    for value, path in zip(values, routes, strict=True):
        try:
            read_route_file(path)
        except InputError as exc:
            raise InputError(source, "study.routes", f"{path}: {exc.problem}", FILE_FIX["routes"]) from None
        if route_set_town(value, path) is not None:
            check_route_set_town(value, path, load_town(town), source, "study.routes",
                                 f'set town = "{{town}}", or drop "{value}" from routes')
    return tuple(map(str, routes))


def _populations() -> PackagedKind:
    return POPULATIONS


def _population(table: dict[str, object] | None, source: str) -> dict | None:
    """The [population] table as given, validated by participants.population."""
    if table is None:
        return None
    return population_table(table, source)  # raises InputError naming the key


# -- the field tables ---------------------------------------------------------------------------------
# Every key of a study config (docs/formats/study_config.md); the rules below check what a table cannot
# (files resolve and load, spec and condition labels distinct, the robust condition's population).

class StudyConfigValues(TypedDict):
    """A study config's checked tables (FIELDS)."""

    study: dict[str, object]
    population: dict[str, object] | None
    drivers: dict[str, object] | None
    questionnaires: dict[str, object] | None
    live: dict[str, object] | None


class LiveValues(TypedDict):
    """The [live] table's checked values (LIVE_FIELDS)."""

    view: str
    driving: str
    inputs: list[str] | None


FileKey = Literal["town", "driver_model", "robust_population"]  # the [study] keys naming a file (FILE_FIX)


class StudyValues(TypedDict):
    """The [study] table's checked values (STUDY_FIELDS)."""

    participants: int
    seed: int
    engine: str
    specs: list[str]
    conditions: list[str]
    name: str | None
    town: str | None
    driver_model: str | None
    horizon: int | None
    fallback_after: int  # or False: the rule disabled
    junction_cap: int
    report_every: int
    belief_rule: BeliefRule
    output: str | None
    policy_cache: str | None
    background_vehicles: int
    routes: Sequence[str]
    record: Sequence[str]
    robust_population: str | None
    robust_objective: str
    belief_source: str | None


class DriversValues(TypedDict):
    """The [drivers] table's checked values (DRIVERS_FIELDS)."""

    population: str


FIELDS = field_table(
    StudyConfigValues,
    Field(key="study", kind=Table(), required=True, problem="missing [study] table",
          missing="missing [study] table",
          fix="add [study] with participants, seed, engine, specs and conditions"),
    # checked in full by participants.population (population_config_from_dict)
    Field(key="population", kind=Table(), problem="expected a table", fix="write a [population] table"),
    Field(key="drivers", kind=Table(), problem="expected a table", fix='write [drivers] population = "FILE"'),
    # checked in full by participants.questionnaires (live studies: docs/live_studies.md)
    Field(key="questionnaires", kind=Table(), problem="expected a table",
          fix='write [questionnaires] after_each_trial = ["jian"]'),
    Field(key="live", kind=Table(), problem="expected a table", fix='write [live] view = "driver"'),
)
TABLES: tuple[str, ...] = keys(FIELDS)
_ENTRIES = ListOf(item=Text(), min_items=1, distinct=True)
_FILE = Text()


def _file_path(seen: Seen) -> str:
    return f"expected a file path, got {shown_value(seen.value)}"


def _study_name(seen: Seen) -> str:
    # the name is the default folder studies/<name>: a path in it would write elsewhere
    if not isinstance(seen.value, str):
        return f"expected a non-empty string, got {shown_value(seen.value)}"
    return f"study name {shown_value(seen.value)} is not {FILE_NAME_RULE} (it names the study's folder)"


FILE_FIX: dict[FileKey | Literal["routes"], str] = {
    "town": "give an existing town file or omit town (the default)",
    "driver_model": "give an existing driver model file or omit driver_model (the default)",
    "robust_population": ("give the driver-population file the robust policy is made for "
                          "(docs/driver_types.md)"),
    "routes": "list existing SUMO route files of background traffic (vehicle types first) or omit routes",
}
STUDY_FIELDS = field_table(
    StudyValues,
    Field(key="participants", kind=ranges.PARTICIPANTS.kind, required=True,
          fix="write the number of participants, e.g. participants = 21",
          missing_fix="add participants = 21"),
    Field(key="seed", kind=ranges.DRAW_SEED.kind, required=True,
          fix="write a non-negative integer, e.g. seed = 1", missing_fix="add seed = 1"),
    Field(key="engine", kind=ENGINE_NAMES, default="sumo", fix=ENGINE_FIX),
    Field(key="specs", kind=_ENTRIES, required=True,
          fix='write specs = ["phi1", "phi2"] (packaged specs) or spec file paths'),
    Field(key="conditions", kind=_ENTRIES, required=True, fix='write conditions = ["aware", "free"]'),
    Field(key="name", kind=Text(pattern=FILE_NAME), problem=_study_name,  # default: the config's stem
          fix='write e.g. name = "paper"; --out or output chooses another folder'),
    Field(key="town", kind=_FILE, problem=_file_path, fix=FILE_FIX["town"]),
    Field(key="driver_model", kind=_FILE, problem=_file_path, fix=FILE_FIX["driver_model"]),
    Field(key="horizon", kind=Integer(minimum=1, maximum=defaults.MAX_HORIZON),
          fix=f"write a positive number of junctions or omit horizon ({DEFAULT_FALLBACK_AFTER})"),
    Field(key="fallback_after", kind=Integer(minimum=0, maximum=defaults.MAX_JUNCTIONS, false_allowed=True),
          default=DEFAULT_FALLBACK_AFTER,
          fix=f"write fallback_after = {DEFAULT_FALLBACK_AFTER}, or false to disable the rule"),
    Field(key="junction_cap", kind=JUNCTION_CAPS, default=DEFAULT_JUNCTION_CAP,
          fix="write e.g. junction_cap = 1"),
    Field(key="report_every", kind=Integer(minimum=1, maximum=10_000), default=1,
          fix="write e.g. report_every = 1"),
    Field(key="belief_rule", kind=BELIEF_RULE_NAMES, default="bayes",
          fix="use 'bayes' or 'paper'"),
    Field(key="output", kind=Text(pattern=PATH_TEXT), fix='write output = "out/paper"',
          problem=lambda seen: f"expected a directory path, got {shown_value(seen.value)}"),
    Field(key="policy_cache", kind=Text(pattern=PATH_TEXT), problem="expected a directory path",
          fix='write policy_cache = "cache/policies" or omit it'),
    Field(key="background_vehicles", kind=ranges.BACKGROUND_VEHICLES.kind, default=0,
          problem=ranges.BACKGROUND_VEHICLES.problem,
          fix=ranges.BACKGROUND_VEHICLES.fix_at(ranges.BACKGROUND_KEY)),
    Field(key="routes", kind=_ENTRIES, default=(), fix=FILE_FIX["routes"]),
    Field(key="record", kind=_ENTRIES, default=(), fix='write record = ["p00000-phi1-aware"]'),
    Field(key="robust_population", kind=_FILE, problem=_file_path, fix=FILE_FIX["robust_population"]),
    Field(key="robust_objective", kind=OneOf(choices=ROBUST_OBJECTIVES, noun="objective"), default="robust",
          fix="use 'robust' (the worst type's value) or 'bayes' (the prior-weighted value)"),
    Field(key="belief_source", kind=OneOf(choices=BELIEF_SOURCES, noun="belief source"),
          fix="use 'true' (simulated studies), 'reported', 'reference' or 'filter', or omit it for the "
              "neutral default (docs/study.md)"),
)
STUDY_KEYS: tuple[str, ...] = keys(STUDY_FIELDS)
DRIVERS_FIX = ("give the path of a driver-population file (docs/driver_type_studies.md), "
               "e.g. population = \"types.json\"")
DRIVERS_FIELDS = field_table(
    DriversValues,
    Field(key="population", kind=_FILE, required=True, problem=_file_path, fix=DRIVERS_FIX),
)
DRIVERS_KEYS: tuple[str, ...] = keys(DRIVERS_FIELDS)
LIVE_FIELDS = field_table(
    LiveValues,
    Field(key="view", kind=OneOf(choices=LIVE_VIEWS, noun="view"), default="driver",
          fix='use view = "driver" (the first-person view) or "map" (the top-down view)'),
    Field(key="driving", kind=OneOf(choices=LIVE_DRIVING, noun="way of driving"), default="assisted",
          fix='use driving = "assisted" (pedal keys, pull out to pass) or "continuous" (wheel and pedals)'),
    Field(key="inputs", kind=ListOf(item=OneOf(choices=LIVE_INPUTS, noun="input"), min_items=1,
                                    distinct=True),
          default=None, fix='list what a participant may drive with, e.g. inputs = ["wheel", "keyboard"] '
                            '(any of "wheel", "gamepad", "keyboard")'),
)


# -- rules ----------------------------------------------------------------------------------------------


def _driver_population(table: dict[str, object] | None, base: Path, source: str) -> str | None:
    """The [drivers] table: the driver-population file, resolved and read (InputError if bad)."""
    if table is None:
        return None
    value = check_fields(table, DRIVERS_FIELDS, source, "study config", "drivers")["population"]
    path = _resolve_path(value, base, source, "drivers.population", "driver-population file", DRIVERS_FIX,
                         _populations())

    load_driver_population(path)  # raises InputError naming the file and the place
    return str(path)


def _specs(values: list[str], base: Path, source: str) -> tuple[str, ...]:
    """Every spec found; file names (stems) distinct, since they label the tables."""
    specs = tuple(str(_resolve_spec(v, base, source, "study.specs")) for v in values)
    if len({Path(s).stem for s in specs}) != len(specs):
        raise InputError(source, "study.specs", "two specs share a file name",
                         "give every spec file a distinct name (the name labels the tables)")
    return specs


def _conditions(values: list[str], base: Path, source: str) -> tuple[str, ...]:
    """Named conditions, or policy files found; labels distinct."""
    fix = 'use "aware", "free", "robust" or a policy file written by trustroute synth'
    conditions = tuple(value if value in NAMED_CONDITIONS else
                       str(_resolve_path(value, base, source, "study.conditions", "policy file", fix))
                       for value in values)
    if len({condition_label(c) for c in conditions}) != len(conditions):
        raise InputError(source, "study.conditions", "two conditions share a name",
                         "give policy files distinct names")
    return conditions


def _optional_file(study: StudyValues, key: FileKey, what: str, base: Path, source: str,
                   packaged: PackagedKind | None = None) -> str | None:
    """The file `study[key]` names (a path, or a name of `packaged`), resolved; None when absent."""
    value = study[key]
    if value is None:
        return None
    return str(_resolve_path(value, base, source, f"study.{key}", what, FILE_FIX[key], packaged))


def _directory(value: str | None, base: Path) -> str | None:
    return None if value is None else str((base / value).resolve())


def _robust_population(study: StudyValues, conditions: tuple[str, ...], base: Path,
                       source: str) -> str | None:
    """The "robust" condition's population file: required with that condition, read and validated."""
    robust_population = _optional_file(study, "robust_population", "driver-population file", base, source,
                                       _populations())
    if robust_population is not None:
        load_driver_population(robust_population)  # raises InputError naming the file and the place
    if "robust" in conditions and robust_population is None:
        raise InputError(source, "study.robust_population", "the 'robust' condition needs the driver "
                         "population its policy is made for",
                         'add robust_population = "types.json" to [study] (docs/driver_types.md)')
    return robust_population


class LiveSettings(TypedDict):
    """StudyConfig's fields from the [live] table."""

    live_view: str
    live_driving: str
    live_inputs: tuple[str, ...]


def _live(table: dict[str, object] | None, source: str) -> LiveSettings:
    """The [live] table's StudyConfig fields; `inputs` choose among continuous driving's inputs."""
    live = check_fields(table or {}, LIVE_FIELDS, source, "study config", "live")
    if live["inputs"] is not None and live["driving"] != "continuous":
        raise InputError(source, "live.inputs", "inputs choose what continuous driving reads, and this "
                         f"study drives {live['driving']!r}",
                         'add driving = "continuous" to [live], or remove inputs')
    inputs = LIVE_INPUTS if live["inputs"] is None else tuple(i for i in LIVE_INPUTS if i in live["inputs"])
    return LiveSettings(live_view=live["view"], live_driving=live["driving"], live_inputs=inputs)


def _belief_source(study: StudyValues, source: str) -> str | None:
    """The declared primary belief source; "true" needs drivers whose models the study knows."""
    declared = study["belief_source"]
    if declared == "true" and study["engine"] == "live":
        raise InputError(source, "study.belief_source", "'true' needs simulated drivers (their own models); "
                         "a live study's drivers are people", "use 'reported' or omit belief_source")
    return declared


def study_config_from_dict(data: object, source: str = "<study>", base: Path | None = None) -> StudyConfig:
    """Validate a parsed study document; relative paths resolve against `base`, then the cwd."""
    base = base if base is not None else Path.cwd()
    if not isinstance(data, dict):
        raise InputError(source, "top level", "expected a TOML table", "start with a [study] table")
    tables = check_fields(data, FIELDS, source, "study config")
    study = check_fields(tables["study"], STUDY_FIELDS, source, "study config", "study")
    specs = _specs(study["specs"], base, source)
    conditions = _conditions(study["conditions"], base, source)
    default_name = Path(source).stem if source.endswith(".toml") else "study"
    name = str(study["name"]) if study["name"] is not None else default_name
    town = _optional_file(study, "town", "town file", base, source, _towns())
    return StudyConfig(
        source_path=source,
        name=name,
        participants=study["participants"],
        seed=study["seed"],
        engine=study["engine"],
        specs=specs,
        conditions=conditions,
        town=town,
        driver_model=_optional_file(study, "driver_model", "driver model file", base, source, DRIVER_MODELS),
        horizon=study["horizon"],
        fallback_after=None if study["fallback_after"] is False else study["fallback_after"],
        junction_cap=study["junction_cap"],
        report_every=study["report_every"],
        belief_rule=study["belief_rule"],
        output=_directory(study["output"] if study["output"] is not None else str(DEFAULT_STUDIES_DIR / name),
                          base),
        policy_cache=outside_packages(_directory(study["policy_cache"], base)),
        background_vehicles=study["background_vehicles"],
        routes=_route_files(study["routes"], town, base, source),
        record=tuple(study["record"]),
        population=_population(tables["population"], source),
        robust_population=_robust_population(study, conditions, base, source),
        robust_objective=study["robust_objective"],
        driver_population=_driver_population(tables["drivers"], base, source),
        questionnaires=_questionnaires(tables["questionnaires"], base, source),
        **_live(tables["live"], source),
        belief_source=_belief_source(study, source),
    )


def _questionnaires(table: dict[str, object] | None, base: Path, source: str) -> dict | None:
    """The [questionnaires] table, checked and its files resolved (participants.questionnaires)."""
    return resolved_table(table, base, source)


def load_study_config(path: str | Path) -> StudyConfig:
    """Read and validate a study config file, or raise InputError."""
    shown = str(path)
    text = read_text(path, shown, "the study config",
                     "pass an existing TOML file (see harness/study/examples/)")
    data = parse_toml(text, shown, "study config")
    return study_config_from_dict(data, shown, Path(path).resolve().parent)


def study_directory(config: StudyConfig, out: str | None) -> Path:
    """Where a study is written: `out`, else the config's output (a loaded config's default is
    studies/<name> in the config's folder), else studies/<name> in the current directory."""
    if out is not None:
        return Path(out)
    if config.output is not None:
        return Path(config.output)
    return DEFAULT_STUDIES_DIR / config.name
