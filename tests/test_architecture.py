"""The package's import graph, read with `ast`: no cycle anywhere (imports inside functions
included), and no module imports another module's `_private` names."""

from __future__ import annotations

import ast
import functools
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def package_modules() -> dict[str, Path]:
    """Module name -> file, for every module of the trustroute namespace (pyproject's package-dir)."""
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    modules: dict[str, Path] = {}
    for package, folder in config["package-dir"].items():
        for path in sorted((REPO / folder).rglob("*.py")):
            parts = path.relative_to(REPO / folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join((package, *parts))] = path
    return modules


@functools.cache
def parsed(path: Path) -> ast.Module:
    """The file's syntax tree, parsed once per session: the checks only read the trees."""
    return ast.parse(path.read_text(), str(path))


def imports(path: Path, module: str, known: dict[str, Path]) -> list[tuple[str, str | None, int]]:
    """(imported module, imported name or None, line) of every import statement in the file."""
    is_package = path.name == "__init__.py"
    out = []
    for node in ast.walk(parsed(path)):
        if isinstance(node, ast.Import):
            out += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".") if is_package else module.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                target = f"{base}.{alias.name}"
                if target in known:
                    out.append((target, None, node.lineno))
                else:
                    out.append((base, alias.name, node.lineno))
    return out


@functools.cache
def package_import_graph() -> dict[str, frozenset[str]]:
    """The package's import graph, read once per session."""
    known = package_modules()
    return {
        module: frozenset(t for t, _, _ in imports(path, module, known) if t in known and t != module)
        for module, path in known.items()
    }


def import_graph() -> dict[str, set[str]]:
    """A copy of the package's import graph of its own: the tests that plant an edge add it there."""
    return {module: set(targets) for module, targets in package_import_graph().items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph[node]):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_graph_is_read():
    graph = import_graph()
    assert "trustroute.harness.study.runner" in graph
    assert "trustroute.harness.study.context" in graph["trustroute.harness.study.runner"]


def test_cycle_detection_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_no_module_imports_another_modules_private_names():
    known = package_modules()
    files = dict(known)
    files.update({f"tests.{p.stem}": p for p in (REPO / "tests").rglob("*.py")})
    offending = [
        f"{path.relative_to(REPO)}:{line}: {name} from {target}"
        for module, path in files.items()
        for target, name, line in imports(path, module, known)
        if target.startswith("trustroute") and target != module and name is not None
        and name.startswith("_") and not name.startswith("__")
    ]
    assert offending == []


# The layers of docs/internals.md, lowest first: a module may import its own layer and the ones
# below, never one above. The longest matching prefix names a module's layer.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("trustroute.core",),
    ("trustroute.networks",),
    ("trustroute.participants",),
    ("trustroute.policies", "trustroute.policies.bracket", "trustroute.policies.model"),
    ("trustroute.policies.logic",),
    ("trustroute.policies.belief",),
    ("trustroute.policies.routing",),
    ("trustroute.policies.evaluation",),
    ("trustroute.policies.synthesis",),
    ("trustroute.policies.trust_state_synthesis",),
    ("trustroute.policies.synthesize_spec", "trustroute.policies.resolve", "trustroute.policies.peer",
     "trustroute.policies.pomdp_py"),
    # the application layer's assembly (trustroute/app/__init__.py): below every entry point
    ("trustroute.app.inputs", "trustroute.app.problem", "trustroute.app.policy",
     "trustroute.app.nets", "trustroute.app.drivers", "trustroute.app.synthesis", "trustroute.app.spec_check",
     "trustroute.app.peers", "trustroute.app.towns", "trustroute.app.populations"),
    ("trustroute.harness", "trustroute.harness.simulation", "trustroute.app.engines"),
    ("trustroute.harness.study", "trustroute.harness.live"),
    ("trustroute.analysis",),
    ("trustroute.app",),   # the runs the API and the CLI start
    ("trustroute",),
    ("trustroute.harness.cli", "trustroute.harness.commands", "trustroute.__main__"),
)


def layer_of(module: str) -> int:
    """The index in LAYERS of the longest prefix of `module` (a package name or a module in it)."""
    best, best_length = -1, -1
    for rank, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_length:
                best, best_length = rank, len(prefix)
    return best


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{module} (layer {layer_of(module)}) imports {target} (layer {layer_of(target)})"
                  for module, targets in graph.items() for target in targets
                  if layer_of(target) > layer_of(module))


def test_every_module_has_a_layer():
    assert [m for m in package_modules() if layer_of(m) < 0] == []


def test_imports_only_point_down():
    assert upward_imports(import_graph()) == []


def test_an_upward_import_is_caught():
    graph = import_graph()
    graph["trustroute.networks.town"] |= {"trustroute.harness.study.runner"}
    graph["trustroute.policies.routing.free"] |= {"trustroute.policies.synthesis.belief_synthesis"}
    found = upward_imports(graph)
    assert any(line.startswith("trustroute.networks.town ") for line in found)
    assert any(line.startswith("trustroute.policies.routing.free ") for line in found)


def test_the_public_api_does_not_import_the_cli():
    graph = import_graph()
    reached, todo = set(), ["trustroute"]
    while todo:
        module = todo.pop()
        if module not in reached:
            reached.add(module)
            todo += sorted(graph.get(module, ()))
    assert sorted(m for m in reached if layer_of(m) == len(LAYERS) - 1) == []


MAX_MODULE_LINES = 600


def test_every_module_stays_small():
    """A module has one job: none of the package's modules runs past MAX_MODULE_LINES lines."""
    long = {module: n for module, path in package_modules().items()
            if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}


def _under(module: str, prefixes: tuple[str, ...]) -> bool:
    return any(module == prefix or module.startswith(prefix + ".") for prefix in prefixes)


# The CLI parses and prints: it reaches the inputs, the policies and the nets through the
# application layer (trustroute/app), never directly.
CLI = ("trustroute.harness.cli", "trustroute.harness.commands")
BEHIND_THE_APP = ("trustroute.policies", "trustroute.networks", "trustroute.participants")


def cli_internal_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{module} imports {target}" for module, targets in graph.items() if _under(module, CLI)
                  for target in targets if _under(target, BEHIND_THE_APP))


def test_the_cli_goes_through_the_application_layer():
    assert cli_internal_imports(import_graph()) == []


def test_a_cli_import_behind_the_application_layer_is_caught():
    graph = import_graph()
    graph["trustroute.harness.commands.run"] |= {"trustroute.policies.resolve"}
    graph["trustroute.harness.cli"] |= {"trustroute.networks.town"}
    graph["trustroute.harness.commands.model"] |= {"trustroute.participants.driver_model"}
    assert cli_internal_imports(graph) == [
        "trustroute.harness.cli imports trustroute.networks.town",
        "trustroute.harness.commands.model imports trustroute.participants.driver_model",
        "trustroute.harness.commands.run imports trustroute.policies.resolve",
    ]


# The analysis reads results; it runs no episode and no study (the runs that feed it, such as the
# fitting command's policy check, are put together in trustroute/app/runs.py).
ANALYSIS = ("trustroute.analysis",)
RUNNING = ("trustroute.harness.simulation", "trustroute.harness.study.runner",
           "trustroute.harness.study.workers", "trustroute.harness.live", "trustroute.app.engines",
           "trustroute.app.runs")


def analysis_running_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{module} imports {target}" for module, targets in graph.items()
                  if _under(module, ANALYSIS) for target in targets if _under(target, RUNNING))


def test_the_analysis_runs_no_simulation():
    assert analysis_running_imports(import_graph()) == []


def test_an_analysis_import_of_a_simulation_is_caught():
    graph = import_graph()
    graph["trustroute.analysis.fitting.posterior_check"] |= {"trustroute.harness.simulation.model_engine"}
    graph["trustroute.analysis.study.analysis"] |= {"trustroute.harness.study.runner"}
    assert analysis_running_imports(graph) == [
        "trustroute.analysis.fitting.posterior_check imports trustroute.harness.simulation.model_engine",
        "trustroute.analysis.study.analysis imports trustroute.harness.study.runner",
    ]
