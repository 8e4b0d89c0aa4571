"""How many of the exact rounding checks fail with a margin removed: the power of the checks whose
counts docs/synthesis.md ("Rounding", "Tested") states, measured.

The checks are tests/policies/synthesis/test_rounding*.py, the `slow` sweeps included. Each variant
runs them in a pytest process of its own (`python -m pytest -p benchmarks.bench_rounding_power`,
the variant named in RUN_ENV) with functions replaced in that process once the tests are collected,
never in the source:

- `no_outward_rounding`: rounding.py's `rounded_down`, `rounded_up` and `widen` give the values as
  computed (no margin, no float outward, no clamp to [0, 1]) in every module of the package and of
  the tests (a check that calls one itself sees the replacement too): the
  synthesis' L and U, the end-component sweeps, `evaluate`'s certified values, the per-type values,
  the mixture, and the trust-state synthesis' L and U;
- `plain_mixture`: a population's mixture (`mixture_lower`, `mixture_upper`) is the plain float
  sum Σ_k w_k V_k: not divided by the weights' sum, not rounded;
- `trust_state_upper_unrounded`: the trust-state synthesis' U is not rounded up (its L still is);
- `bayes_margin_for_the_authors_rule`: every margin (`relative_margin`) takes the Bayes units, which
  grow linearly with the depth, under the authors' rule too, whose own grow with its square.

One row per variant: the failed checks out of all, the same for the suite's share (the checks not
marked `slow`), per file, and per test with its failing parameters. No timing: a measurement of
what the checks see. `python -m benchmarks bench_rounding_power` runs every variant (about a minute
of CPU); `python -m benchmarks.bench_rounding_power VARIANT ...` the ones named.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CHECKS = ("tests/policies/synthesis/test_rounding.py", "tests/policies/synthesis/test_rounding_population.py",
          "tests/policies/synthesis/test_rounding_paper.py",
          "tests/policies/synthesis/test_rounding_trust_state.py")
# Hands the variant and the result file to the pytest process: "VARIANT:PATH".
RUN_ENV = "TRUSTROUTE_BENCH_ROUNDING_RUN"
# The modules whose names are replaced.
HOLDERS = ("trustroute.", "tests.")
ROUNDING = "trustroute.policies.synthesis.rounding"
POPULATION = "trustroute.policies.synthesis.population"
TRUST_STATE = "trustroute.policies.trust_state_synthesis.synthesis"
# The one check of the rounding functions themselves, which a variant replaces: left out.
OF_THE_FUNCTIONS = ("tests/policies/synthesis/test_rounding.py::"
                    "test_widening_keeps_zero_and_one_and_moves_the_rest_outward")


def _as_computed(values, margin: float = 0.0) -> np.ndarray:
    """`rounded_down` or `rounded_up` without the margin, the float outward and the clamp."""
    return np.asarray(values, dtype=float)


def _widen_as_computed(lower: float, upper: float, margin: float = 0.0) -> tuple[float, float]:
    return float(lower), float(upper)


def _plain_lower(weights, values) -> float:
    return float(np.asarray(weights) @ np.array([v.lower for v in values]))


def _plain_upper(weights, values) -> float:
    return float(np.asarray(weights) @ np.array([v.upper for v in values]))


@dataclass(frozen=True)
class Patch:
    """`name` of module `source` replaced by `replace(original)` in every loaded module of the
    package or the tests that holds the original (`within` None), or in module `within` only."""

    source: str
    name: str
    replace: Callable[[Callable], Callable]
    within: str | None = None


def _bayes_units(original: Callable) -> Callable:
    """`relative_margin` with the Bayes units whatever the rule: linear in the depth, where the
    authors' rule's grow with its square."""
    return lambda rounding, depth, rule: original(rounding, depth, "bayes")


VARIANTS: dict[str, tuple[Patch, ...]] = {
    "no_outward_rounding": (Patch(ROUNDING, "rounded_down", lambda _: _as_computed),
                            Patch(ROUNDING, "rounded_up", lambda _: _as_computed),
                            Patch(ROUNDING, "widen", lambda _: _widen_as_computed)),
    "plain_mixture": (Patch(POPULATION, "mixture_lower", lambda _: _plain_lower),
                      Patch(POPULATION, "mixture_upper", lambda _: _plain_upper)),
    "trust_state_upper_unrounded": (Patch(ROUNDING, "rounded_up", lambda _: _as_computed,
                                          within=TRUST_STATE),),
    "bayes_margin_for_the_authors_rule": (Patch(ROUNDING, "relative_margin", _bayes_units),),
}


def apply(patches: Iterable[Patch]) -> list[str]:
    """Replace each patch's original wherever it applies; the "module.name" of every replacement.
    Names imported later (inside functions) read the source module's, which is replaced too."""
    done = []
    for patch in patches:
        original = getattr(importlib.import_module(patch.source), patch.name)
        holders = ([importlib.import_module(patch.within)] if patch.within is not None else
                   [m for n, m in sorted(sys.modules.items()) if n.startswith(HOLDERS) and m is not None])
        for module in holders:
            if vars(module).get(patch.name) is original:
                setattr(module, patch.name, patch.replace(original))
                done.append(f"{module.__name__}.{patch.name}")
    return done


class _Recorder:
    """The pytest plugin of one variant's run: replaces the functions once the tests are collected
    (their modules imported) and records every check's outcome and whether it is `slow`."""

    def __init__(self, variant: str, path: Path):
        self.variant, self.path = variant, path
        self.slow: dict[str, bool] = {}
        self.failed: dict[str, str] = {}
        self.replaced: list[str] = []

    def pytest_collection_finish(self, session) -> None:
        self.slow = {item.nodeid: item.get_closest_marker("slow") is not None for item in session.items}
        self.replaced = apply(VARIANTS[self.variant])

    def pytest_runtest_logreport(self, report) -> None:
        if report.failed:
            errors = [line[1:].strip() for line in report.longreprtext.splitlines() if line.startswith("E ")]
            self.failed[report.nodeid] = (errors or ["?"])[0][:300]

    def pytest_sessionfinish(self, session) -> None:
        self.path.write_text(json.dumps({"slow": self.slow, "failed": self.failed,
                                         "replaced": self.replaced}))


def pytest_configure(config) -> None:
    """Registers the recorder when this module is loaded as a plugin (`-p`) with RUN_ENV set."""
    if RUN_ENV in os.environ:
        variant, _, path = os.environ[RUN_ENV].partition(":")
        config.pluginmanager.register(_Recorder(variant, Path(path)), "rounding_power_recorder")


def measure(variant: str, checks: Iterable[str] = CHECKS) -> dict:
    """Run `checks` (files or node ids) with `variant`'s functions replaced; its row."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "outcome.json"
        env = {**os.environ, RUN_ENV: f"{variant}:{path}", "OPENBLAS_NUM_THREADS": "1"}
        subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                        "-p", "benchmarks.bench_rounding_power", "--deselect", OF_THE_FUNCTIONS, *checks],
                       cwd=REPO, env=env, stdout=subprocess.DEVNULL, check=False)
        outcome = json.loads(path.read_text())
    return summary(variant, outcome["slow"], outcome["failed"], outcome["replaced"])


def _count(nodeids: list[str], failed: dict[str, str]) -> dict:
    return {"failed": sum(n in failed for n in nodeids), "checks": len(nodeids)}


def _parameters(nodeid: str) -> tuple:
    """A node id's parameters, numbers as numbers (seed 2 before seed 10)."""
    inside = nodeid.partition("[")[2].rstrip("]")
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p) for p in inside.split("-"))


def summary(variant: str, slow: dict[str, bool], failed: dict[str, str], replaced: list[str]) -> dict:
    """The row: failed of all checks and of the suite's share, per file, per test (its failing
    parameters, each with the first line of its assertion)."""
    ids = sorted(slow)
    files: dict[str, list[str]] = {}
    tests: dict[str, list[str]] = {}
    for nodeid in ids:
        files.setdefault(nodeid.split("::")[0], []).append(nodeid)
        tests.setdefault(nodeid.split("[")[0], []).append(nodeid)

    def suite(nodes: list[str]) -> dict:
        return _count([n for n in nodes if not slow[n]], failed)

    return {"name": f"rounding_power_{variant}", "value": _count(ids, failed)["failed"],
            "unit": "failed checks", "checks": len(ids), "suite": suite(ids), "replaced": replaced,
            "files": {name: {**_count(nodes, failed), "suite": suite(nodes)}
                      for name, nodes in files.items()},
            "tests": {name: {**_count(nodes, failed),
                             "failing": {n.partition("[")[2].rstrip("]"): failed[n]
                                         for n in sorted(nodes, key=_parameters) if n in failed}}
                      for name, nodes in tests.items()}}


def run() -> list[dict]:
    return [measure(variant) for variant in VARIANTS]


if __name__ == "__main__":
    for row in (measure(v) for v in (sys.argv[1:] or VARIANTS)):
        print(json.dumps(row), flush=True)
