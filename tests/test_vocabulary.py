"""One vocabulary across the package, read with `ast`: a road id "U-V" is taken apart only by
`networks/road.py`'s `Road`; no function takes more than eight parameters (settings objects
instead); module-level caches only where they keep what was read from disk; no capability probes
(`hasattr`, `getattr` with a default) outside a listed few."""

from __future__ import annotations

import ast
import functools

from tests.test_architecture import package_modules, parsed


@functools.cache
def package_trees() -> dict[str, ast.Module]:
    """Module name -> parsed source, for every module of the package (parsed once per session, the
    trees shared with the import-graph checks)."""
    return {module: parsed(path) for module, path in package_modules().items()}


def with_added(module: str, source: str) -> dict[str, ast.Module]:
    """The package's trees with `source` appended to `module` (a deliberate violation)."""
    trees = dict(package_trees())
    trees[module] = ast.Module(body=[*trees[module].body, *ast.parse(source).body], type_ignores=[])
    return trees


# -- road ids -------------------------------------------------------------------------------------
ROAD_MODULE = "trustroute.networks.road"
SPLITTERS = {"split", "rsplit", "partition", "rpartition"}


def road_splits_outside_road(trees: dict[str, ast.Module]) -> list[str]:
    """module:line of every split of a string on "-" (`x.split("-")`, `x.partition("-")`, ...)
    outside networks/road.py."""
    return sorted(f"{module}:{node.lineno}" for module, tree in trees.items() if module != ROAD_MODULE
                  for node in ast.walk(tree)
                  if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr in SPLITTERS and node.args
                  and isinstance(node.args[0], ast.Constant) and node.args[0].value == "-")


def test_only_road_splits_road_ids():
    assert road_splits_outside_road(package_trees()) == []


def test_a_hand_split_is_caught():
    trees = with_added("trustroute.networks.town", "def arrived(road):\n    return road.split('-')[1]\n")
    trees["trustroute.harness.live.view"] = ast.parse('u, _, v = road.rpartition("-")\n')
    found = road_splits_outside_road(trees)
    assert [f.split(":")[0] for f in found] == ["trustroute.harness.live.view", "trustroute.networks.town"]


# -- at most 8 parameters -------------------------------------------------------------------------
# Settings travel as frozen dataclasses (policies/synthesis/settings.py, policies/evaluation/
# settings.py), whose generated constructors are not function definitions here.
MAX_PARAMETERS = 8
# Functions still above the limit, each by "module:function" (none now: a function that needs
# more takes a settings object instead; an entry here must name a function still above the limit).
OVER_THE_LIMIT: frozenset[str] = frozenset()


def parameter_count(node: ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) -> int:
    """Every parameter (positional, keyword-only, *args, **kwargs) but a leading self or cls."""
    args = node.args
    names = [a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)]
    if names and names[0] in ("self", "cls"):
        names = names[1:]
    return len(names) + (args.vararg is not None) + (args.kwarg is not None)


def long_signatures(trees: dict[str, ast.Module]) -> set[str]:
    return {f"{module}:{getattr(node, 'name', 'lambda')}" for module, tree in trees.items()
            for node in ast.walk(tree)
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
            and parameter_count(node) > MAX_PARAMETERS}


def test_no_new_function_takes_more_than_eight_parameters():
    found = long_signatures(package_trees())
    assert found - OVER_THE_LIMIT == set()
    assert OVER_THE_LIMIT - found == set(), "these are within the limit now: remove them from the list"


def test_a_long_signature_is_caught():
    trees = with_added("trustroute.networks.town", "def route(a, b, c, d, e, f, g, h, i=1):\n    return a\n")
    # eight besides self: within the limit
    trees["trustroute.networks.road"] = ast.parse(
        "class Mover:\n    def move(self, a, b, c, d, e, f, g, h):\n        return a\n")
    assert long_signatures(trees) - OVER_THE_LIMIT == {"trustroute.networks.town:route"}


# -- module-level caches only at I/O boundaries ---------------------------------------------------
# A module-level mapping or a memoised function hides who builds what; one is allowed where it
# keeps what was read from disk (a net, a binary's path, the importer's own source) or holds a
# registry. Each entry is "module:name".
IO_CACHES = frozenset({
    "trustroute.networks.real_net:_ROADS",              # a town's SUMO net read with sumolib
    "trustroute.harness.live.view:net_view",            # a net file read for the station's view
    "trustroute.harness.simulation.sumo_start:sumo_binary",   # SUMO's binary found on disk
    "trustroute.networks.cities:importer_fingerprint",  # the importer's source files read
    "trustroute.harness.simulation.sumo_start:_NET_FACTS",   # read off the running SUMO's net
    "trustroute.networks.town:BUILT_TOWNS",             # a registry of built towns, not a cache
})
# Caches of computed objects still to be replaced by the object passed down from where it is made
# (a function's cache that goes must leave this list).
COMPUTED_CACHES: frozenset[str] = frozenset()
MAPPINGS = {"dict", "OrderedDict", "defaultdict", "WeakValueDictionary", "WeakKeyDictionary"}
MEMOISERS = {"cache", "lru_cache"}


def module_caches(trees: dict[str, ast.Module]) -> set[str]:
    """module:name of every module-level empty mapping and every memoised function."""
    found = set()
    for module, tree in trees.items():
        for node in tree.body:
            if isinstance(node, ast.Assign | ast.AnnAssign) and node.value is not None:
                value = node.value
                mapping = (isinstance(value, ast.Dict) and not value.keys) or (
                    isinstance(value, ast.Call) and not value.args
                    and getattr(value.func, "id", getattr(value.func, "attr", None)) in MAPPINGS)
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                found |= {f"{module}:{t.id}" for t in targets if mapping and isinstance(t, ast.Name)}
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                for decorator in node.decorator_list:
                    called = decorator.func if isinstance(decorator, ast.Call) else decorator
                    if getattr(called, "id", getattr(called, "attr", None)) in MEMOISERS:
                        found.add(f"{module}:{node.name}")
    return found


def test_module_level_caches_are_only_the_listed_ones():
    found = module_caches(package_trees())
    assert found - IO_CACHES - COMPUTED_CACHES == set()
    assert (IO_CACHES | COMPUTED_CACHES) - found == set(), "gone: remove them from the lists"


def test_a_new_module_level_cache_is_caught():
    trees = with_added("trustroute.policies.logic.spec", "_SPECS: dict[str, object] = {}\n")
    trees["trustroute.networks.road"] = ast.parse(
        "import functools\n\n@functools.lru_cache(maxsize=8)\ndef parsed(text):\n    return text\n")
    assert module_caches(trees) - IO_CACHES - COMPUTED_CACHES == {
        "trustroute.policies.logic.spec:_SPECS", "trustroute.networks.road:parsed"}


# -- no capability probes -------------------------------------------------------------------------
# What an object can do is its type's to say (isinstance of a class or a protocol), not
# `hasattr(x, "name")` or `getattr(x, "name", default)`. Reading an attribute by a computed name that
# must exist (`getattr(record, field.name)`, a command's function by name) is not a probe. The probes
# that stay read optional attributes of modules and objects this package does not define, each as
# "module:attribute" with why.
ALLOWED_PROBES = {
    "trustroute.core.output_files:O_CLOEXEC": "os: the flag exists on some platforms only",
    "trustroute.core.validation:O_CLOEXEC": "os: the flag exists on some platforms only",
    "trustroute.harness.simulation.sumo_start:libsumo": "SUMO's module: libsumo, or TraCI for sumo-gui",
    "trustroute.harness.simulation.sumo_start:_libsumo": "libsumo's native module, not in every build",
    "trustroute.harness.simulation.sumo_start:_libsumo_step":
        "libsumo's step, wrapped when libsumo.start(traceFile=...) traces",
    "trustroute.harness.simulation.sumo_start:__qualname__": "the name of that (maybe absent) step",
    "trustroute.policies.peer.paynt:BeliefExplorationModelCheckerOptionsDouble":
        "stormpy: only the versions that build SAYNT have it",
}


def capability_probes(trees: dict[str, ast.Module]) -> set[str]:
    """module:attribute of every `hasattr(x, "a")` and `getattr(x, "a", default)` ("<computed>"
    for a name that is not a string constant)."""
    found = set()
    for module, tree in trees.items():
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and (node.func.id, len(node.args)) in {("hasattr", 2), ("getattr", 3)}):
                name = node.args[1]
                attribute = name.value if isinstance(name, ast.Constant) else "<computed>"
                found.add(f"{module}:{attribute}")
    return found


def test_no_capability_probes():
    found = capability_probes(package_trees())
    assert found - set(ALLOWED_PROBES) == set()
    assert set(ALLOWED_PROBES) - found == set(), "gone: remove them from ALLOWED_PROBES"


def test_a_capability_probe_is_caught():
    trees = with_added("trustroute.harness.simulation.episode",
                       "def is_person(driver):\n    return getattr(driver, 'is_person', False)\n")
    trees["trustroute.networks.road"] = ast.parse(
        "def tabled(policy, name):\n    return hasattr(policy, 'table') or hasattr(policy, name)\n"
        "def field(record, name):\n    return getattr(record, name)\n")   # by name: not a probe
    assert capability_probes(trees) - set(ALLOWED_PROBES) == {
        "trustroute.harness.simulation.episode:is_person", "trustroute.networks.road:table",
        "trustroute.networks.road:<computed>"}


# -- imports at module top ------------------------------------------------------------------------
# The command line (which loads a command's modules only when it runs) and the API's entry
# (`import trustroute` stays cheap) import inside functions; elsewhere an import sits at the top
# of its module, unless it is a heavy or optional library loaded only by the function that needs
# it: the top-level package names below, each with why.
LAZY_ENTRIES = ("trustroute", "trustroute.harness.cli", "trustroute.harness.commands", "trustroute.__main__")
HEAVY_OR_OPTIONAL = {
    "stormpy": "optional extra (peer checkers)",
    "paynt": "optional extra (peer checkers)",
    "rerun": "optional viewer, loaded only with --rrd",
    "sumolib": "SUMO's tools: reading a net is done only where a net is read",
    "sumo": "SUMO's data files, located only when a net is converted",
    "libsumo": "SUMO itself, started only by sumo_start (one of libsumo or traci)",
    "traci": "SUMO itself, started only by sumo_start (one of libsumo or traci)",
    "distributed": "dask, only for a study on a scheduler",
    "matplotlib": "plots only",
    "scipy": "statistics only",
    "statsmodels": "statistics only",
    "jinja2": "the report only",
    "tqdm": "progress bars only",
    "uvicorn": "the live station's server only",
    "websockets": "the scripted live participant only",
    "multiprocessing": "a process start method chosen where processes start",
    "pyarrow": "tables only (a package's rules, read by every output check, need none)",
}
# Imports still inside functions of modules being reworked elsewhere (module -> imported modules);
# an entry that moves to the top is to leave this list.
PENDING_IMPORTS = {
    "trustroute.analysis.belief_sources": {
        "trustroute.harness.study.plan", "trustroute.harness.study.replay",
        "trustroute.participants.driver_population", "trustroute.policies.belief.driver_types",
        "trustroute.policies.model.trust_pomdp"},
    "trustroute.analysis.fitting.posterior_check": {
        "trustroute.core.packaged", "trustroute.harness.simulation.episode_tracker",
        "trustroute.harness.simulation.model_engine", "trustroute.networks.town",
        "trustroute.participants.driver_model", "trustroute.policies.logic.spec",
        "trustroute.policies.resolve"},
    "trustroute.app.peers": {"trustroute.policies.peer.storm"},
    "trustroute.harness.live.replay": {
        "trustroute.harness.simulation.episode", "trustroute.harness.simulation.rerun_log",
        "trustroute.harness.study.context", "trustroute.harness.study.parts",
        "trustroute.harness.study.replay", "trustroute.networks.sumo_net"},
    "trustroute.harness.live.scripted": {
        "trustroute.app.drivers", "trustroute.harness.live.server",
        "trustroute.participants.synthetic_driver"},
    "trustroute.harness.live.server": {
        "numpy", "trustroute.core.dataset", "trustroute.core.validation", "trustroute.harness.live.view",
        "trustroute.harness.study.expected",
        "trustroute.harness.study.manifest", "trustroute.harness.study.resume",
        "trustroute.harness.study.runner", "trustroute.networks.sumo_net"},
    "trustroute.harness.live.worker": {
        "os", "trustroute.harness.study.context", "trustroute.harness.study.parts",
        "trustroute.harness.simulation.sumo_start", "trustroute.harness.study.runner",
        "trustroute.harness.study.workers"},
    "trustroute.harness.simulation.background": {"gzip", "xml.etree.ElementTree"},
    "trustroute.harness.simulation.episode": {"trustroute.harness.simulation.rerun_log"},
    "trustroute.harness.simulation.gym_env": {
        "trustroute.harness.simulation.episode", "trustroute.harness.simulation.episode_tracker",
        "trustroute.harness.simulation.model_engine", "trustroute.policies.model.trust_pomdp"},
    "trustroute.harness.simulation.sumo_files": {"xml.etree.ElementTree"},
    "trustroute.harness.simulation.sumo_start": {"os"},
    "trustroute.harness.study.context": {
        "trustroute.networks.town", "trustroute.participants.driver_model",
        "trustroute.participants.driver_population", "trustroute.policies.logic.spec",
        "trustroute.policies.resolve"},
    "trustroute.harness.study.expected": {
        "trustroute.policies.belief.problem", "trustroute.policies.evaluation.settings",
        "trustroute.policies.evaluation.trust_state", "trustroute.policies.model.trust_pomdp",
        "trustroute.policies.routing.decision_tables", "trustroute.policies.routing.files",
        "trustroute.policies.synthesis.rounding"},
    "trustroute.harness.study.replay": {
        "trustroute.core.dataset", "trustroute.harness.simulation.sumo_start",
        "trustroute.harness.study.inputs", "trustroute.harness.study.manifest",
        "trustroute.harness.study.runner"},
    "trustroute.harness.study.runner": {
        "re", "socket", "trustroute.core.output_files", "trustroute.harness.simulation.episode",
        "trustroute.harness.simulation.model_engine", "trustroute.harness.simulation.sumo_start",
        "trustroute.harness.study.workers", "trustroute.participants.synthetic_driver"},
}


def function_imports(trees: dict[str, ast.Module]) -> set[tuple[str, str]]:
    """(module, imported module) of every import inside a function, outside the lazy entries."""
    found = set()
    for module, tree in trees.items():
        if module == "trustroute" or module.startswith(LAZY_ENTRIES[1:]):
            continue
        for function in ast.walk(tree):
            if not isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(function):
                if isinstance(node, ast.Import):
                    found |= {(module, alias.name) for alias in node.names}
                elif isinstance(node, ast.ImportFrom):
                    found.add((module, "." * node.level + (node.module or "")))
    return found


def unexplained_imports(trees: dict[str, ast.Module]) -> set[tuple[str, str]]:
    return {(module, target) for module, target in function_imports(trees)
            if target.split(".")[0] not in HEAVY_OR_OPTIONAL
            and target not in PENDING_IMPORTS.get(module, set())}


def test_imports_sit_at_module_top():
    assert unexplained_imports(package_trees()) == set()


def test_a_new_function_level_import_is_caught():
    trees = with_added("trustroute.networks.town",
                       "def later():\n    import json\n    from trustroute.core import errors\n"
                       "    import matplotlib.pyplot as plt\n    return json, errors, plt\n")
    assert unexplained_imports(trees) == {("trustroute.networks.town", "json"),
                                          ("trustroute.networks.town", "trustroute.core")}
