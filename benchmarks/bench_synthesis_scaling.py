"""How synthesis scales: grid towns of 12 to 200 junctions, 3 to 8 waypoint sets, H 10/20/40/unbounded.

Each cell of the table is one `synthesize(tau=1e-3, time_limit=60)` run in a fresh subprocess (so
its peak RSS is its own): seconds, peak RSS (MB), L, U, and whether the issue's target is met
(gap <= 1e-3 within 60 s and under 1 GB). The spec is
`F (v1 & F (v2 & ... F (vk & hightrust)))` with each waypoint set the two directed roads of one
street, the sets spread over the grid; incidents are drawn with a seeded generator. Beside it the
paper's town, phi1 and phi2 at H = 20 (target: within 1 s).
The table is printed to stderr; the rows are the benchmark's JSON lines.

SCALING_QUICK=1 runs a reduced table: the 200-junction targets (5 waypoint sets, H = 20, 40,
unbounded) and short sweeps over junctions, horizon and waypoints. The machine is shared: seconds
are wall-clock under whatever load there is; compare rows within one run.
Run: `.venv/bin/python -m benchmarks bench_synthesis_scaling`.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from trustroute.policies.synthesis.settings import SynthesisSettings

GRIDS = {12: (3, 4), 50: (5, 10), 100: (10, 10), 200: (10, 20)}
WAYPOINTS = (3, 5, 8)
HORIZONS = (10, 20, 40, None)
TAU = 1e-3
TIME_LIMIT = 60.0
MEMORY_TARGET_MB = 1024.0
PAPER_TARGET_SECONDS = 1.0


def grid_town_dict(rows: int, columns: int, seed: int) -> dict:
    import numpy as np

    rng = np.random.default_rng(seed)
    junctions = {f"J{r}_{c}": [100.0 * c, 100.0 * r] for r in range(rows) for c in range(columns)}
    roads = [[f"J{r}_{c}", f"J{r}_{c + 1}"] for r in range(rows) for c in range(columns - 1)]
    roads += [[f"J{r}_{c}", f"J{r + 1}_{c}"] for r in range(rows - 1) for c in range(columns)]
    incidents = {}
    kinds = ("none", "none", "pedestrian", "obstacle", "truck")
    for u, v in roads:
        for a, b in ((u, v), (v, u)):
            incidents[f"{a}-{b}"] = kinds[int(rng.integers(len(kinds)))]
    return {"junctions": junctions, "roads": roads, "incidents": incidents}


def grid_spec_text(rows: int, columns: int, waypoints: int) -> str:
    """Waypoint i is the street around the i-th of `waypoints` points spread along the grid."""
    roads = []
    for i in range(waypoints):
        cell = int(round((i + 1) * (rows * columns - 1) / waypoints))
        r, c = divmod(cell, columns)
        c2 = c + 1 if c + 1 < columns else c - 1
        roads.append([f"J{r}_{c}-J{r}_{c2}", f"J{r}_{c2}-J{r}_{c}"])
    formula = f"F (v{waypoints} & hightrust)"
    for i in range(waypoints - 1, 0, -1):
        formula = f"F (v{i} & {formula})"
    lines = ['name = "grid"', 'start = "J0_1-J0_0"', f'formula = "{formula}"', "[states]"]
    lines += [f"v{i + 1} = {json.dumps(r)}" for i, r in enumerate(roads)]
    lines += ["[beliefs.hightrust]", "coeffs = [0, 0, 0, 0, 0, 1, 1]", "offset = 0.5"]
    return "\n".join(lines) + "\n"


def grid_or_paper_problem(junctions: int, waypoints: int, paper_spec: str | None):
    """(pomdp, spec): the paper's town with specs/<paper_spec>.toml, or the grid town of `junctions`
    junctions (GRIDS) with `waypoints` waypoint sets."""
    from trustroute.networks.town import load_town, town_from_dict
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec, spec_from_text
    from trustroute.policies.model.trust_pomdp import build_pomdp

    driver = load_driver_model()
    if paper_spec is not None:
        town = load_town()
        spec = load_spec(f"specs/{paper_spec}.toml", town)
    else:
        rows, columns = GRIDS[junctions]
        town = town_from_dict(grid_town_dict(rows, columns, seed=junctions), "<grid town>")
        spec = spec_from_text(grid_spec_text(rows, columns, waypoints), "<grid spec>", town)
    return build_pomdp(town, driver), spec


def _child(junctions: int, waypoints: int, horizon: int | None, paper_spec: str | None) -> dict:
    """Runs in the subprocess: one synthesis, its numbers and the process's peak RSS."""
    from benchmarks.timing import peak_rss_mb
    from trustroute.policies.synthesis.belief_synthesis import synthesize

    pomdp, spec = grid_or_paper_problem(junctions, waypoints, paper_spec)
    result = synthesize(pomdp, spec, SynthesisSettings(tau=TAU, time_limit=TIME_LIMIT, horizon=horizon))
    rss_mb = peak_rss_mb()
    last = result.stats.runs[-1]
    return {"lower": result.lower, "upper": result.upper, "seconds": result.seconds, "rss_mb": rss_mb,
            "nodes": last.nodes, "completion_closed": last.completion_closed}


def run_json_subprocess(module: str, arguments: list, timeout: float) -> dict:
    """`python -m module ARGUMENTS_JSON` in a fresh process (its own peak RSS, no warm caches); the
    dict its last stdout line holds, or {"error": its last stderr line}."""
    done = subprocess.run([sys.executable, "-m", module, json.dumps(arguments)],
                          capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        return {"error": done.stderr.strip().splitlines()[-1] if done.stderr.strip() else "failed"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def _run_child(junctions: int, waypoints: int, horizon: int | None, paper_spec: str | None = None) -> dict:
    return run_json_subprocess("benchmarks.bench_synthesis_scaling",
                               [junctions, waypoints, horizon, paper_spec], TIME_LIMIT * 5)


def _configurations() -> list[tuple[int, int, int | None]]:
    if os.environ.get("SCALING_QUICK"):
        # the targets (200 junctions, 5 waypoint sets, H 20/40/unbounded) and one sweep each
        # over junctions, horizon and waypoints
        return ([(12, 3, 10), (12, 3, 20), (50, 3, 20), (50, 3, 40), (50, 5, 20), (50, 8, 20)]
                + [(200, 5, h) for h in (20, 40, None)])
    return [(j, w, h) for j in GRIDS for w in WAYPOINTS for h in HORIZONS]


def run() -> list[dict]:
    results = []
    table = [f"{'junctions':>9} {'waypoints':>9} {'H':>9} {'seconds':>8} {'RSS MB':>7} "
             f"{'L':>8} {'U':>8} target"]
    for name in ("phi1", "phi2"):
        out = _run_child(12, 3, 20, name)
        met = ("error" not in out and out["seconds"] <= PAPER_TARGET_SECONDS
               and out["upper"] - out["lower"] <= TAU)
        results.append({"name": f"synthesis_scaling.paper.{name}.H20", "value": out.get("seconds"),
                        "unit": "s", **out, "target": f"gap <= {TAU} within {PAPER_TARGET_SECONDS} s",
                        "target_met": bool(met)})
        if "error" not in out:
            table.append(f"{'paper ' + name:>9} {'':>9} {20:>9} {out['seconds']:8.2f} {out['rss_mb']:7.0f} "
                         f"{out['lower']:8.4f} {out['upper']:8.4f} {'yes' if met else 'no'}")
    for junctions, waypoints, horizon in _configurations():
        out = _run_child(junctions, waypoints, horizon)
        label = "unbounded" if horizon is None else str(horizon)
        met = ("error" not in out and out["upper"] - out["lower"] <= TAU
               and out["seconds"] <= TIME_LIMIT * 1.02 and out["rss_mb"] < MEMORY_TARGET_MB)
        results.append({"name": f"synthesis_scaling.grid{junctions}.w{waypoints}.{label}",
                        "value": out.get("seconds"), "unit": "s", "junctions": junctions,
                        "waypoints": waypoints, "horizon": horizon, **out,
                        "target": f"gap <= {TAU} within {TIME_LIMIT:.0f} s under {MEMORY_TARGET_MB:.0f} MB",
                        "target_met": bool(met)})
        if "error" in out:
            table.append(f"{junctions:>9} {waypoints:>9} {label:>9} error: {out['error'][:60]}")
        else:
            table.append(f"{junctions:>9} {waypoints:>9} {label:>9} {out['seconds']:8.2f} "
                         f"{out['rss_mb']:7.0f} {out['lower']:8.4f} {out['upper']:8.4f} "
                         f"{'yes' if met else 'no'}")
        print(table[-1], file=sys.stderr, flush=True)
    print("\n".join(table), file=sys.stderr, flush=True)
    return results


if __name__ == "__main__":
    junctions, waypoints, horizon, paper_spec = json.loads(sys.argv[1])
    print(json.dumps(_child(junctions, waypoints, horizon, paper_spec)))
