"""How closely `trustroute synth` keeps its --time-limit as a whole command, start-up included.

The README's robust example, `trustroute synth phi1 --horizon 20 --population
driver_population_three_types --objective robust --time-limit T --json`, with T = 2, 5, 20 and 60 s,
three runs each, every run a fresh process timed from outside (interpreter start, imports, reading
the inputs, every synthesis run and exact evaluation, writing the policy file). The target: wall
time at most T plus 10 % of T, and at least 1 s more. Beside each run: the bounds, the policy's
rows, `fallback_only`, the seconds synthesis itself reported, the process's CPU seconds and the
1-minute load average (the machine is shared: above 2 on its 2 cores, wall time includes the wait
for a core). bench_synthesis_time_limit times the synthesis call alone.
Run: `.venv/bin/python -m benchmarks bench_command_time_limit` (about 5 minutes).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

LIMITS = (2.0, 5.0, 20.0, 60.0)
REPEATS = 3
COMMAND = ("synth", "phi1", "--horizon", "20", "--population", "driver_population_three_types",
           "--objective", "robust", "--json")


def allowed(limit: float) -> float:
    """The wall time a command with `limit` may take: the limit plus 10 %, at least 1 s more."""
    return limit + max(0.1 * limit, 1.0)


def one_run(limit: float, out: Path) -> dict:
    load = os.getloadavg()[0]
    cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "trustroute", *COMMAND, "--time-limit", f"{limit:g}",
                           "--out", str(out)], capture_output=True, text=True, check=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_seconds = (after.ru_utime - cpu.ru_utime) + (after.ru_stime - cpu.ru_stime)
    answer = json.loads(done.stdout)
    return {"name": f"command_time_limit_robust_{limit:g}s", "time_limit": limit, "seconds": wall,
            "allowed_seconds": allowed(limit), "within_target": wall <= allowed(limit),
            "cpu_seconds": cpu_seconds, "cpu_within_target": cpu_seconds <= allowed(limit),
            "synthesis_seconds": answer["seconds"], "lower": answer["lower"], "upper": answer["upper"],
            "policy_rows": answer["stats"]["policy_rows"], "fallback_only": answer["fallback_only"],
            "load": load}


def run() -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for limit in LIMITS:
            for repeat in range(REPEATS):
                rows.append(one_run(limit, Path(tmp) / f"robust-{limit:g}-{repeat}.json"))
    print("| limit s | wall s | CPU s | allowed s | wall within | synthesis s | L | U | rows | fallback only "
          "| load |", file=sys.stderr)
    print("|---|---|---|---|---|---|---|---|---|---|---|", file=sys.stderr)
    for r in rows:
        print(f"| {r['time_limit']:g} | {r['seconds']:.2f} | {r['cpu_seconds']:.2f} | "
              f"{r['allowed_seconds']:.1f} | "
              f"{'yes' if r['within_target'] else 'NO'} | {r['synthesis_seconds']:.2f} | {r['lower']:.4f} | "
              f"{r['upper']:.4f} | {r['policy_rows']} | {r['fallback_only']} | {r['load']:.2f} |",
              file=sys.stderr)
    return rows
