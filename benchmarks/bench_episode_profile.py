"""Where the milliseconds of one SUMO episode go, phase by phase, beside the bare libsumo loops.

The bare loop is timed twice, each in a process of its own: starting and closing SUMO
(`bare`) and keeping its simulation open as the episodes do (`bare_open`, bench_episode's row
`episode_phi1_vs_bare_kept_open`: what the harness adds to SUMO's stepping of the same route).

The same episode and bare loop as bench_episode (phi1, trust-free policy, default driver,
incidents, logs handed back as Arrow tables), run `EPISODES` times each, alternating, each side in
a process of its own as in bench_episode (the episodes one after another in one process, as a
study's worker runs them: the first starts SUMO, the others return it to its empty state). Each phase
is timed by wrapping the function that does it, in wall time and in this thread's CPU time
(libsumo runs in it; CPU time is what a shared machine's load disturbs least: a call that waits
for a core shows in wall time only), a clock pair per call, a few hundred calls per episode; the
wrappers are removed afterwards. Phases:

- `sumo_start`, `sumo_steps`, `sumo_close`: libsumo's native start, simulation step and close
  (the bare loop's every run; the episode steps more objects and, with its incidents, more sim
  time);
- `sumo_reset`: the episode's return of the open simulation to its empty state (loadState);
- `insert_ego`: the ego's type, route, insertion and subscription;
- `commit`: the road's end (of it `inject`, the next road's incident objects; `close_road`, the
  driver's trust, report and the tracker's record with the filter; `next_junction`, the tracker's
  decision point);
- `choose`: the answer to the decision point (the tracker's record of the junction);
- `watch`: the live incident's per-step work and the driver's view check;
- `loop_python`: the rest of the step loop (the subscription read, logging, monitor);
- `roads_table`, `kinematics_table`, `incidents_table`: the logs as Arrow tables;
- `other`: the rest of the call (setup, net checks, the driver's generator).

Then, in as many runs again with no phase timed, every function of libsumo's native module is timed
instead (`libsumo_cpu`, `libsumo_wall`, `libsumo_calls`, beside those runs' `libsumo_run_cpu` and
`libsumo_run_wall` totals): the part of each side that is SUMO's own work (its steps, reset,
queries, `vehicle.add`, `setRoute`, the subscription reads), which no change to the Python can
remove; each call's clock pair adds under a microsecond to it. `libsumo_by_function_cpu` splits it
by function (`functions_table`), and `sumo_alone_vs_bare_kept_open_cpu` sets it against the whole
bare loop kept open: "timed" with the clocks' cost, "lower" without it (`sumo_alone_ratio`).

Each figure is ms per episode (total over the run / EPISODES), with the 1-minute load average.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections import defaultdict
from collections.abc import Callable, Iterator

from benchmarks.bench_episode import measured_episode
from benchmarks.timing import ForkedCalls
from trustroute.harness.simulation import episode as episode_module
from trustroute.harness.simulation import episode_tracker

EPISODES = 40
BY_FUNCTION_SHOWN = 14      # libsumo functions listed one by one, the rest summed
MIN_CALLS_CHEAPEST = 10     # calls per episode for a function's mean to stand for a timer's cost

# (owner, attribute, phase): the functions whose time is a phase of the episode.
# `run` is the episode's every `advance` (SUMO's start and close, the loop, the road ends and the
# logs all run inside it); the road's end is its `commit` (the road closed, the decision point) and
# `extend` (the route one road ahead, then `inject`), the policy's answer `choose` (outside).
_EPISODE_PHASES = (
    (episode_module.SumoEpisode, "insert_ego", "insert_ego"),
    (episode_module.SumoEpisode, "commit", "commit"),
    (episode_module.SumoEpisode, "extend", "commit"),
    (episode_module.SumoEpisode, "choose", "choose"),
    (episode_module.SumoEpisode, "inject", "inject"),
    (episode_module.SumoEpisode, "close_road", "close_road"),
    (episode_module.SumoEpisode, "watch", "watch"),
    (episode_module.SumoEpisode, "advance", "run"),
    (episode_module.SumoEpisode, "incidents_table", "incidents_table"),
    (episode_module.SumoEpisode, "kinematics_table", "kinematics_table"),
    (episode_tracker.EpisodeTracker, "decision_point", "next_junction"),
    (episode_tracker.EpisodeTracker, "roads_table", "roads_table"),
)
_PARTS_OF_COMMIT = ("inject", "close_road", "next_junction")   # timed inside `commit`
_NATIVE_PHASES = (("simulation_start", "sumo_start"), ("simulation_saveState", "sumo_start"),
                  ("simulation_loadState", "sumo_reset"), ("simulation_step", "sumo_steps"),
                  ("simulation_close", "sumo_close"))
_SUMO_PHASES = ("sumo_start", "sumo_reset", "sumo_steps", "sumo_close")


def _timed(function, phase: str, totals: dict[str, float], cpu: dict[str, float], counts: dict[str, int]):
    def timed(*args, **kwargs):
        started, started_cpu = time.perf_counter(), time.thread_time()
        try:
            return function(*args, **kwargs)
        finally:
            totals[phase] += time.perf_counter() - started
            cpu[phase] += time.thread_time() - started_cpu
            counts[phase] += 1
    return timed


def _is_api(native, name: str) -> bool:
    """A function of libsumo's API in its native module ("vehicle_add"; not SWIG's helpers)."""
    return (name[:1].islower() and "_" in name and "swig" not in name
            and not name.startswith(("new_", "delete_")) and callable(getattr(native, name)))


@contextlib.contextmanager
def _phase_timers(totals: dict[str, float], cpu: dict[str, float], counts: dict[str, int],
                  all_native: bool = False) -> Iterator[None]:
    """Wrap every phase's function for the duration of the block (then put the originals back);
    all_native: instead every function of libsumo's native module, each its own phase (its name)."""
    import libsumo._libsumo as native

    originals = []
    if all_native:
        targets = [(native, name, name) for name in dir(native) if _is_api(native, name)]
    else:
        targets = [(owner, name, phase) for owner, name, phase in _EPISODE_PHASES]
        targets += [(native, name, phase) for name, phase in _NATIVE_PHASES]
    try:
        for owner, name, phase in targets:
            function = getattr(owner, name)
            originals.append((owner, name, function))
            setattr(owner, name, _timed(function, phase, totals, cpu, counts))
        yield
    finally:
        for owner, name, function in reversed(originals):
            setattr(owner, name, function)


def _per_episode(totals: dict[str, float], wall: float, episodes: int) -> dict[str, float]:
    ms = {phase: 1e3 * seconds / episodes for phase, seconds in totals.items()}
    row = {phase: ms.get(phase, 0.0) for phase in _SUMO_PHASES}
    if "run" in ms:
        tables = ("roads_table", "kinematics_table", "incidents_table")
        inside_run = (*_SUMO_PHASES, "insert_ego", "commit", "watch", *tables)
        row.update({phase: ms.get(phase, 0.0) for phase in
                    ("insert_ego", "commit", *_PARTS_OF_COMMIT, "watch", "choose")})
        row["loop_python"] = ms["run"] - sum(ms.get(phase, 0.0) for phase in inside_run)
        row.update({phase: ms.get(phase, 0.0) for phase in tables})
        counted = ms["run"] + row["choose"]
    else:
        counted = sum(row.values())
    row["other"] = 1e3 * wall / episodes - counted
    row["total"] = 1e3 * wall / episodes
    return {phase: round(value, 3) for phase, value in row.items()}


def _profiled(run: Callable[[], object]) -> Callable[[str], dict | None]:
    """`run` behind one call: "warm" runs it untimed, "run" runs it under the phase timers,
    "native" under timers on every function of libsumo's, "totals" returns what the timers
    summed (called in its own process: ForkedCalls)."""
    timers = {"wall": defaultdict(float), "cpu": defaultdict(float), "counts": defaultdict(int),
              "total": [0.0, 0.0], "native_wall": defaultdict(float), "native_cpu": defaultdict(float),
              "native_counts": defaultdict(int), "native_total": [0.0, 0.0]}

    def call(what: str) -> dict | None:
        if what == "totals":
            return {key: dict(value) if isinstance(value, defaultdict) else value
                    for key, value in timers.items()}
        if what == "warm":
            run()
            return None
        prefix = "native_" if what == "native" else ""
        with _phase_timers(timers[f"{prefix}wall"], timers[f"{prefix}cpu"], timers[f"{prefix}counts"],
                           all_native=what == "native"):
            started, started_cpu = time.perf_counter(), time.thread_time()
            run()
            timers[f"{prefix}total"][0] += time.perf_counter() - started
            timers[f"{prefix}total"][1] += time.thread_time() - started_cpu
        return None

    return call


def profile(episodes: int = EPISODES) -> dict:
    """Per-phase ms of the episode and of both bare loops over `episodes` alternating runs each."""
    measured = measured_episode()
    with (ForkedCalls(_profiled(measured.episode)) as episode, ForkedCalls(_profiled(measured.bare)) as bare,
          ForkedCalls(_profiled(measured.bare_kept_open)) as bare_open):
        sides = {"episode": episode, "bare": bare, "bare_open": bare_open}
        for side in sides.values():
            side("warm")   # the episode's first run starts SUMO
        load_before = os.getloadavg()[0]
        for _ in range(episodes):
            for side in sides.values():
                side("run")
        for _ in range(episodes):
            for side in sides.values():
                side("native")
        totals = {name: side("totals") for name, side in sides.items()}
    out = {"name": "episode_phi1_phases", "unit": "ms per episode", "episodes": episodes}
    for clock, index in (("wall", 0), ("cpu", 1)):
        for side in sides:
            out[f"{side}_{clock}"] = _per_episode(totals[side][clock], totals[side]["total"][index], episodes)
        ratio = out[f"episode_{clock}"]["total"] / out[f"bare_{clock}"]["total"]
        out[f"ratio_of_totals_{clock}"] = round(ratio, 3)
        ratio = out[f"episode_{clock}"]["total"] / out[f"bare_open_{clock}"]["total"]
        out[f"ratio_of_totals_kept_open_{clock}"] = round(ratio, 3)
    out["steps"] = {side: totals[side]["counts"].get("sumo_steps", 0) // episodes for side in totals}
    for side in sides:
        for clock, index in (("wall", 0), ("cpu", 1)):
            native = sum(totals[side][f"native_{clock}"].values())
            out.setdefault(f"libsumo_{clock}", {})[side] = round(1e3 * native / episodes, 3)
            run_total = totals[side]["native_total"][index]
            out.setdefault(f"libsumo_run_{clock}", {})[side] = round(1e3 * run_total / episodes, 3)
        calls = sum(totals[side]["native_counts"].values())
        out.setdefault("libsumo_calls", {})[side] = round(calls / episodes, 1)
    out["libsumo_by_function_cpu"] = by_function(totals, episodes)
    out["sumo_alone_vs_bare_kept_open_cpu"] = sumo_alone_ratio(totals, out["bare_open_cpu"]["total"],
                                                               episodes)
    out["load_average_1min"] = [load_before, os.getloadavg()[0]]
    return out


def by_function(totals: dict, episodes: int, shown: int = BY_FUNCTION_SHOWN) -> dict[str, dict]:
    """libsumo's functions by the episode's CPU in them, the most first: [ms, calls] per episode
    for the episode and the bare loop kept open; the rest summed as "others"."""
    cpu = {side: totals[side]["native_cpu"] for side in ("episode", "bare_open")}
    counts = {side: totals[side]["native_counts"] for side in ("episode", "bare_open")}
    names = sorted(set(cpu["episode"]) | set(cpu["bare_open"]), key=lambda n: -cpu["episode"].get(n, 0.0))
    out: dict[str, dict] = {}
    for i, name in enumerate(names):
        key = name if i < shown else "others"
        for side in cpu:
            ms, calls = out.setdefault(key, {}).get(side, (0.0, 0.0))
            out[key][side] = (ms + 1e3 * cpu[side].get(name, 0.0) / episodes,
                              calls + counts[side].get(name, 0) / episodes)
    return {name: {side: [round(ms, 3), round(calls, 1)] for side, (ms, calls) in row.items()}
            for name, row in out.items()}


def sumo_alone_ratio(totals: dict, bare_open_ms: float, episodes: int) -> dict[str, float]:
    """The episode's libsumo CPU alone against the whole bare loop kept open (its CPU total with
    no function timed): "timed" as measured, timers included; "lower" less, for every call, the
    cheapest mean per call of any function called at least MIN_CALLS_CHEAPEST times per episode,
    which is more than a timer costs (that call's own work is in it), so no less than SUMO's work."""
    cpu, counts = totals["episode"]["native_cpu"], totals["episode"]["native_counts"]
    ms = 1e3 * sum(cpu.values()) / episodes
    calls = sum(counts.values()) / episodes
    cheapest = min(1e3 * cpu[name] / counts[name] for name in cpu
                   if counts[name] >= MIN_CALLS_CHEAPEST * episodes)
    return {"timed": round(ms / bare_open_ms, 3), "lower": round((ms - calls * cheapest) / bare_open_ms, 3),
            "cheapest_call_ms": round(cheapest, 5)}


def functions_table(row: dict) -> str:
    """libsumo's CPU by function (docs/performance.md): ms and calls per episode on each side."""
    lines = ["| libsumo function | episode CPU ms | calls | bare kept open CPU ms | calls |",
             "|---|---|---|---|---|"]
    for name, sides in row["libsumo_by_function_cpu"].items():
        (ms, calls), (bare_ms, bare_calls) = sides["episode"], sides["bare_open"]
        lines.append(f"| {name} | {ms:.3f} | {calls:g} | {bare_ms:.3f} | {bare_calls:g} |")
    return "\n".join(lines)


def run() -> list[dict]:
    return [profile()]


def phases_table(row: dict) -> str:
    """The profile as a Markdown table (docs/performance.md): CPU and wall ms per episode, the
    difference against the bare loop kept open."""
    lines = ["| phase | episode CPU | bare kept open CPU | CPU difference | bare CPU | episode wall "
             "| bare kept open wall |",
             "|---|---|---|---|---|---|---|"]
    for phase, value in row["episode_cpu"].items():
        bare_open = row["bare_open_cpu"].get(phase, 0.0)
        name = f"of it: {phase}" if phase in _PARTS_OF_COMMIT else phase
        lines.append(f"| {name} | {value:.2f} | {bare_open:.2f} | {value - bare_open:+.2f} | "
                     f"{row['bare_cpu'].get(phase, 0.0):.2f} | {row['episode_wall'][phase]:.2f} | "
                     f"{row['bare_open_wall'].get(phase, 0.0):.2f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    import json

    _row = profile()
    print(json.dumps(_row))
    print(phases_table(_row))
    print(functions_table(_row))
