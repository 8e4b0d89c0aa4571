"""Import the authors' CARLA study logs (trust_level_record CSVs) into a study directory.

One CSV per (driver, trial, condition) has one row per CARLA tick: the displayed trust level
(1-7), the location as "(x, y, road_id, lane_id)" of the lane-centre waypoint, whether the
autopilot was on, and the belief the AV logged. This module

- names every file (driver, trial, if_baseline) and classifies it: study episode, warm-up
  (trial 3), pilot (driver 0 / pilot_study), or the authors' sample copies, and reads it with
  every cell checked (analysis/carla_study/log_file.py);
- cuts each episode into directed roads the way their simulator did: a road ends at the first
  tick within 15 m of the arrival point of its state (state_location.csv), and the next road is
  the successor state whose arrival point the vehicle reaches next;
- per road records the takeover (any tick with the autopilot off), the trust displayed on
  arrival, the number of trust changes, the AV's logged belief, and the exact Bayes filter of
  the packaged driver model run on the observed incidents and takeovers;
- writes the dataset's episodes.parquet, roads.parquet, kinematics.parquet (positions, thinned)
  and manifest.json through trustroute.core.dataset, and beside them real_episodes.parquet,
  real_roads.parquet and ticks.parquet (lossless run-length encoding of trust and autopilot).

The format is documented in docs/real_study.md. Bad input raises InputError (one line, exit 2).
"""

from __future__ import annotations

import json
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from trustroute.analysis.carla_study.log_file import read_log
from trustroute.analysis.carla_study.log_schema import (
    REAL_EPISODES_FILE,
    REAL_EPISODES_SCHEMA,
    REAL_ROADS_FILE,
    REAL_ROADS_SCHEMA,
    TICKS_FILE,
    TICKS_SCHEMA,
)
from trustroute.analysis.carla_study.town01 import ARRIVAL_RADIUS_M, CarlaTables, load_carla_tables
from trustroute.analysis.satisfaction import satisfaction_by_source
from trustroute.core import dataset
from trustroute.core.errors import InputError
from trustroute.core.output_files import check_output_dir
from trustroute.core.package import sha256_of
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.core.progress import bar_disable
from trustroute.core.validation import csv_place
from trustroute.core.wording import counted
from trustroute.harness.study.inputs import SPEC_SHA256
from trustroute.harness.study.manifest import git_revision, package_versions
from trustroute.harness.study.resume import check_own_folder, study_files
from trustroute.networks.road import Road
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp

# --sync runs CARLA with settings.fixed_delta_seconds = 0.05 (the driver script's game_loop)
TICK_SECONDS = 0.05
LOG_NAME = re.compile(
    r"trust_level_record_driver_(?P<driver>\d+)_trial_(?P<trial>\d+)_if_baseline_(?P<baseline>[01])"
    r"(?P<tag>.*)\.csv$"
)
# A tick farther than this from every Town01 spawn point is on no road of the study. Spawn points
# line every road of Town01; the largest distance of any logged tick in the released logs is
# reported by the importer (manifest "max_distance_to_spawn_point_m") and is far below this.
OFF_ROAD_M = 60.0
# log_end of a log cut before its route's end (`log_ending`); the import's summary names such logs
LOG_TRUNCATED = "truncated"
KINEMATICS_EVERY = 25  # ticks between kept positions in kinematics.parquet (ticks.parquet is lossless)
# The session order of the README: the warm-up (trial 3), then trial 1 aware, trial 1 baseline, trial 2
# aware, trial 2 baseline. An episode's position is its place among the study sessions, 0-based as
# in every study (docs/dataset.md): the warm-up is driven first but is no episode.
WARM_UP_SESSION = (3, 0)
STUDY_SESSIONS = ((1, 0), (1, 1), (2, 0), (2, 1))
EXPECTED_FILES = (WARM_UP_SESSION, *STUDY_SESSIONS)
CONDITIONS = {0: "aware", 1: "free"}
IMPORTED_SPECS = ("phi1.toml", "phi2.toml")   # the packaged specs the authors' study drove


def session_name(driver: int, trial: int, baseline: int) -> str:
    """A driver's session as the manifest's `missing_sessions` and the import's summary name it:
    the warm-up as the warm-up (its file's trial 3 and condition are no trial of the study), a
    study session by its trial and condition."""
    if (trial, baseline) == WARM_UP_SESSION:
        return f"driver {driver} warm-up"
    return f"driver {driver} trial {trial} {CONDITIONS[baseline]}"


@dataclass(frozen=True)
class LogFile:
    path: Path
    relative: str
    driver: int
    trial: int
    baseline: int
    role: str  # "study", "warmup", "pilot", "sample"

    @property
    def episode_id(self) -> str:
        return f"d{self.driver:02d}-t{self.trial}-{CONDITIONS[self.baseline]}"


def classify(path: Path, root: Path) -> LogFile | None:
    match = LOG_NAME.search(path.name)
    if match is None:
        return None
    relative = str(path.relative_to(root)) if path.is_relative_to(root) else path.name
    driver, trial, baseline = int(match["driver"]), int(match["trial"]), int(match["baseline"])
    tag = match["tag"]
    lowered = relative.lower()
    if "sample" in tag or "sample_data" in lowered:
        role = "sample"
    elif "pilot" in lowered or driver == 0 or "warmup" in tag:
        role = "pilot"  # driver 0 is the experimenters' test id (README: --driver_id 0)
    elif trial == 3:
        role = "warmup"
    else:
        role = "study"
    if trial not in (1, 2, 3):
        raise InputError(
            relative,
            "file name",
            f"unknown trial {trial} (the study ran trials 1, 2 and 3)",
            "remove the file or rename it to trial_1, trial_2 or trial_3",
        )
    return LogFile(path, relative, driver, trial, baseline, role)


@dataclass(frozen=True)
class RoadCut:
    state: str  # the authors' state name, e.g. "F1"
    first: int  # first tick row of the road
    last: int  # last tick row (the arrival tick, or the log's last row if not arrived)
    arrived: bool


def cut_roads(xy: np.ndarray, trial: int, tables: CarlaTables, relative: str = "") -> list[RoadCut]:
    """The simulator's road sequence: a road ends at the first tick within ARRIVAL_RADIUS_M of its
    state's arrival point; the next road is the successor state reached first afterwards."""
    info = tables.trials[trial]
    state, first = info["start"], 0
    cuts: list[RoadCut] = []
    while True:
        target = np.asarray(tables.arrival_point[state])
        within = np.flatnonzero(np.hypot(*(xy[first:] - target).T) <= ARRIVAL_RADIUS_M)
        if within.size == 0:
            cuts.append(RoadCut(state, first, len(xy) - 1, False))
            return cuts
        arrival = first + int(within[0])
        cuts.append(RoadCut(state, first, arrival, True))
        candidates = tables.successors(state)
        if Road.parse(tables.road_of_state[state]).to_junction == info["goal"]:
            candidates = [*candidates, state]  # the policy's stay-at-goal action (a3)
        best: tuple[int, str] | None = None
        for candidate in candidates:
            point = np.asarray(tables.arrival_point[candidate])
            # the candidate is reached after leaving the current arrival zone
            rest = xy[arrival + 1 :]
            gone = np.flatnonzero(np.hypot(*(rest - target).T) > ARRIVAL_RADIUS_M)
            start = int(gone[0]) if gone.size else len(rest)
            hit = np.flatnonzero(np.hypot(*(rest[start:] - point).T) <= ARRIVAL_RADIUS_M)
            if hit.size and (best is None or start + int(hit[0]) < best[0]):
                best = (start + int(hit[0]), candidate)
        if best is None:
            # the log ends on the next road before its arrival: which road is it? The nearest
            # successor arrival point to the last tick.
            if arrival + 1 >= len(xy):
                return cuts
            last = xy[-1]
            nearest = min(
                candidates, key=lambda s: float(np.hypot(*(last - np.asarray(tables.arrival_point[s]))))
            )
            cuts.append(RoadCut(nearest, arrival + 1, len(xy) - 1, False))
            return cuts
        state, first = best[1], arrival + 1


def log_ending(roads: pd.DataFrame, goal: str) -> tuple[str, str]:
    """(end_reason, log_end) of an episode from its roads (`directed_road`, `arrived`).

    The authors' script writes the log when the car arrives at the last state of its route (the
    arrival whose next state is the end token: `World.check_destination` -> `World.destroy`), so a
    complete log's last row is the arrival at the goal junction (76 of the 77 released study logs),
    or the goal was reached before the run was stopped (d06-t1-free reached L by E-L, not by its
    preset K-L, drove on and ended 247 ticks later on the road). A log whose car never arrived at
    the goal junction was cut before the route's end: LOG_TRUNCATED (its end_reason stays `cap`, an
    episode that did not finish: the dataset's reasons have none for a cut log)."""
    # the car reached the goal junction on some road (their run ends there, or loops on)
    reached_goal = bool((roads["arrived"] & roads["directed_road"].str.endswith(f"-{goal}")).any())
    if not reached_goal:
        return "cap", LOG_TRUNCATED
    return "destination", "arrived" if bool(roads["arrived"].iloc[-1]) else "log ended on the road"


def check_on_road(ticks: pd.DataFrame, tables: CarlaTables, log: LogFile) -> float:
    """The largest distance of a tick from every Town01 spawn point; InputError past OFF_ROAD_M."""
    xy = ticks[["x", "y"]].to_numpy()
    d = np.sqrt(((xy[:, None, :] - tables.spawn_points[None, :, :]) ** 2).sum(-1)).min(axis=1)
    worst = int(np.argmax(d))
    if d[worst] > OFF_ROAD_M:
        raise InputError(
            log.relative,
            csv_place(log.path, worst, "location"),
            f"({xy[worst, 0]:.1f}, {xy[worst, 1]:.1f}) maps to no road of Town01 "
            f"({d[worst]:.0f} m from the nearest spawn point, limit {OFF_ROAD_M:.0f} m)",
            "pass an unmodified log of the authors' Town01 study",
        )
    return float(d[worst])


def episode_tables(
    log: LogFile, ticks: pd.DataFrame, tables: CarlaTables, driver_model, town
) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """(episode row, roads frame, run-length ticks frame) of one log."""
    cuts = cut_roads(ticks[["x", "y"]].to_numpy(), log.trial, tables, log.relative)
    pomdp = build_pomdp(town, driver_model)
    trust = ticks["trust"].to_numpy()
    auto = ticks["autopilot"].to_numpy()
    beliefs = np.stack(ticks["belief"].to_numpy())
    belief = np.asarray(driver_model.initial_belief, dtype=float)
    rows, road_of_tick = [], np.zeros(len(ticks), dtype=np.int64)
    for i, cut in enumerate(cuts):
        road = tables.road_of_state[cut.state]
        span = slice(cut.first, cut.last + 1)
        road_of_tick[span] = i
        takeover = bool((~auto[span]).any()) if i > 0 else False
        incident = tables.incidents[road] if i > 0 else "none"
        before = belief.copy()
        if i > 0:
            belief = pomdp.filter(before, driver_model.incident_index(incident), int(takeover))[0][0]
        segment = trust[span]
        rows.append(
            {
                "episode_id": log.episode_id,
                "index": i,
                "directed_road": road,
                "action": None,
                "incident": incident,
                "takeover": takeover if i > 0 else None,  # the start road has no observation
                "performance": "succ" if i > 0 else None,  # their model has no AV performance
                "trust_before": None,
                "trust_after": None,  # hidden trust: unknown for real participants
                "reported_trust": int(trust[cut.last]),
                "belief_before": before.tolist(),
                "belief_after": belief.tolist(),
                "dfa_state": -1,  # not run at import; analysis evaluates the specs
                "fallback": False,
                "sim_time_in": float(ticks["tick"].iloc[cut.first]) * TICK_SECONDS,
                "sim_time_out": float(ticks["tick"].iloc[cut.last]) * TICK_SECONDS,
                "tick_first": int(ticks["tick"].iloc[cut.first]),
                "tick_last": int(ticks["tick"].iloc[cut.last]),
                # real-study columns (docs/real_study.md)
                "authors_state": cut.state,
                # the middle tick: the logged belief changes a tick after the simulator's arrival
                # test, whose position (the vehicle's) differs slightly from the logged waypoint
                "logged_belief": beliefs[(cut.first + cut.last) // 2].tolist(),
                "arrived": cut.arrived,
                "ticks": int(cut.last - cut.first + 1),
                "manual_ticks": int((~auto[span]).sum()),
                "trust_changes": int((segment[1:] != segment[:-1]).sum())
                + int(i > 0 and trust[cut.first] != trust[cut.first - 1]),
            }
        )
    for i in range(len(rows) - 1):
        rows[i]["action"] = Road.parse(rows[i + 1]["directed_road"]).to_junction
    roads = pd.DataFrame(rows)
    for column in ("takeover",):
        roads[column] = roads[column].astype("boolean")
    for column in ("trust_before", "trust_after"):
        roads[column] = roads[column].astype("Int64")
    carla_road = ticks["carla_road"].to_numpy()
    change = (
        np.flatnonzero(
            (trust[1:] != trust[:-1])
            | (auto[1:] != auto[:-1])
            | (road_of_tick[1:] != road_of_tick[:-1])
            | (carla_road[1:] != carla_road[:-1])
        )
        + 1
    )
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change - 1, [len(ticks) - 1]])
    runs = pd.DataFrame(
        {
            "episode_id": log.episode_id,
            "tick_first": ticks["tick"].to_numpy()[starts],
            "tick_last": ticks["tick"].to_numpy()[ends],
            "rows": ends - starts + 1,  # log rows in the run (a row per tick in the authors' logs)
            "road_index": road_of_tick[starts],
            "carla_road": carla_road[starts],
            "trust": trust[starts],
            "autopilot": auto[starts],
        }
    )
    driven = roads.iloc[1:]
    end_reason, log_end = log_ending(roads, tables.trials[log.trial]["goal"])
    episode = {
        "episode_id": log.episode_id,
        "participant": log.driver,
        "position": STUDY_SESSIONS.index((log.trial, log.baseline)),
        "spec": tables.trials[log.trial]["spec"],
        "condition": CONDITIONS[log.baseline],
        "seed": -1,  # a real participant: no seed
        "trial": log.trial,
        "source_file": log.relative,
        "junctions": int(len(roads) - 1),
        "takeovers": int(driven["takeover"].sum()),
        "final_trust": None,  # hidden trust: unknown (the displayed trust is final_reported_trust)
        "final_reported_trust": int(trust[-1]),
        "mean_trust": None,
        "fallback_fired": bool(log.baseline == 0 and len(roads) - 1 > 20),
        "end_reason": end_reason,
        "log_end": log_end,
        "sim_seconds": float(ticks["tick"].iloc[-1] - ticks["tick"].iloc[0]) * TICK_SECONDS,
        "wall_seconds": 0.0,  # not run by trustroute
        "ticks": int(len(ticks)),
        "manual_ticks": int((~auto).sum()),
        "mean_reported_trust": float(driven["reported_trust"].mean()) if len(driven) else float("nan"),
        "reports": int(len(driven)),
        "driver_type": None,  # a real participant's type is not known
        **dict.fromkeys(dataset.EPISODE_MANUAL_MEASURES),   # no takeover measures in the logs
        "trust_changes": int((trust[1:] != trust[:-1]).sum()),
    }
    return episode, roads, runs


SOURCE_FIX = "pass a checkout of the authors' repository, a folder of their CSVs or one of their CSVs"
LOG_PATTERN = "trust_level_record_driver_*_trial_*_if_baseline_*.csv"   # LOG_NAME, as a reader types it


def discover(source: Path) -> list[LogFile]:
    """The logs of `source`: every CSV under a folder, or one log file. A file is named by its
    relative path under the folder, and a single log by its file name."""
    source = Path(source)
    if not source.exists():
        raise InputError(str(source), "", "no such file or directory", SOURCE_FIX)
    paths, root = (sorted(source.rglob("*.csv")), source) if source.is_dir() else ([source], source.parent)
    # the statistic_test/ under the folder given holds copies of the same files, read as subsets
    # (`authors_subsets`), not episodes; where the folder itself lies does not matter
    logs = [c for p in paths if "statistic_test" not in p.relative_to(root).parts
            and (c := classify(p, root)) is not None]
    if not logs:
        problem = f"no {LOG_PATTERN} files" if source.is_dir() else f"not a {LOG_PATTERN} file"
        raise InputError(str(source), "", problem, SOURCE_FIX)
    return logs


def check_import_target(out: Path, logs: list[LogFile]) -> None:
    """Before anything is written: `out` is new or empty (a folder of other files is refused, as a
    study's --out is: `check_own_folder`), or is an earlier import of the same logs (the same files
    found), which is imported again in place."""
    found = study_files(out)
    if not found:
        check_own_folder(out)
        return
    try:
        manifest = dataset.read_manifest(out)
    except InputError:
        manifest = {}
    real = manifest.get("real_study")
    inventory = real.get("inventory") if isinstance(real, dict) else None
    earlier = ({str(entry.get("file")) for entry in inventory if isinstance(entry, dict) and "role" in entry}
               if isinstance(inventory, list) else None)
    if manifest.get("engine") == dataset.CARLA_LOGS_ENGINE and earlier == {log.relative for log in logs}:
        return
    raise InputError(str(out), "--out", f"holds a study ({', '.join(found[:3])}) that is not an import of "
                     "these logs", "pass another --out: a new or empty directory")


def authors_subsets(source: Path) -> dict[str, list[str]]:
    """The file lists of statistic_test/ (the subsets the authors' scripts read), by folder."""
    root = Path(source) / "statistic_test"
    out = {}
    if root.is_dir():
        for folder in sorted(p for p in root.rglob("*") if p.is_dir()):
            names = sorted(p.name for p in folder.glob("*.csv"))
            if names:
                out[str(folder.relative_to(root))] = names
    return out


def import_carla_logs(
    source: Path, out: Path, echo=None, listed_absent: list[str] | None = None, progress: bool = False
) -> dict:
    """Convert the logs under `source` into the study directory `out`; return the manifest.

    `listed_absent`: files the source's index lists but whose content is absent (the git tree of
    the authors' repository lists 14 CSVs whose blobs were never stored); recorded as absent."""
    source, out = Path(source), Path(out)
    check_output_dir(out, "--out", "study directory")
    tables = load_carla_tables()
    town, driver_model = load_town(None), load_driver_model(None)
    logs = discover(source)
    check_import_target(out, logs)
    seen: dict[str, LogFile] = {}
    inventory, episode_rows, road_frames, run_frames, kin_frames = [], [], [], [], []
    worst_distance = 0.0
    from tqdm import tqdm

    iterator = tqdm(logs, desc="import", unit="log", disable=bar_disable(progress))
    for log in iterator:
        entry = {
            "file": log.relative,
            "driver": log.driver,
            "trial": log.trial,
            "condition": CONDITIONS[log.baseline],
            "role": log.role,
        }
        ticks = read_log(log.path, log.relative)
        worst_distance = max(worst_distance, check_on_road(ticks, tables, log))
        if log.role != "study":
            entry["status"] = {
                "warmup": "warm-up trial, not analysed",
                "pilot": "pilot/test driver, excluded",
                "sample": "authors' sample copy, excluded",
            }[log.role]
            inventory.append(entry)
            continue
        if log.episode_id in seen:
            raise InputError(
                log.relative,
                "file name",
                f"a second log of {log.episode_id} (first: {seen[log.episode_id].relative})",
                "keep one log per driver, trial and condition",
            )
        seen[log.episode_id] = log
        episode, roads, runs = episode_tables(log, ticks, tables, driver_model, town)
        entry.update(
            {
                "status": "imported",
                "episode_id": log.episode_id,
                "roads": int(len(roads)),
                "end_reason": episode["end_reason"],
                "log_end": episode["log_end"],
            }
        )
        inventory.append(entry)
        episode_rows.append(episode)
        road_frames.append(roads)
        run_frames.append(runs)
        kept = ticks.iloc[::KINEMATICS_EVERY]
        seconds = kept["tick"].to_numpy(dtype=float) * TICK_SECONDS
        step = np.hypot(np.diff(kept["x"].to_numpy()), np.diff(kept["y"].to_numpy()))
        speed = np.concatenate([[0.0], step / np.maximum(np.diff(seconds), TICK_SECONDS)])
        kin_frames.append(
            pd.DataFrame(
                {
                    "episode_id": log.episode_id,
                    "time": seconds,
                    "x": kept["x"].to_numpy(),
                    "y": kept["y"].to_numpy(),
                    "speed": speed,  # of the logged waypoint, over the kept ticks
                    "lane": (
                        kept["carla_road"].astype(str) + ":" + kept["carla_lane"].astype(str)
                    ).to_numpy(),
                    "mode": np.where(kept["autopilot"].to_numpy(), "autopilot", "manual"),
                }
            )
        )
        if echo is not None:
            echo(f"  {log.relative}: {counted(len(roads), 'road')}, {episode['end_reason']}, "
                 f"{episode['log_end']}")
    for name in listed_absent or []:
        inventory.append({"file": name, "status": "listed but absent (no content in the source)"})
    drivers = sorted({log.driver for log in logs if log.role in ("study", "warmup")})
    missing = []
    for d in drivers:
        have = {
            (log.trial, log.baseline) for log in logs if log.driver == d and log.role in ("study", "warmup")
        }
        missing += [session_name(d, t, b) for t, b in EXPECTED_FILES if (t, b) not in have]
    episodes = pd.DataFrame(episode_rows).sort_values(["participant", "position"], kind="stable")
    order = list(episodes["episode_id"])
    roads = pd.concat(road_frames, ignore_index=True)
    roads = roads.iloc[
        np.argsort(roads["episode_id"].map({e: i for i, e in enumerate(order)}).to_numpy(), kind="stable")
    ]
    episodes["satisfied"] = _logged_satisfaction(episodes, roads, town, driver_model)
    out.mkdir(parents=True, exist_ok=True)
    write_checked(episodes, dataset.EPISODES_SCHEMA, out / dataset.EPISODES_FILE)
    write_checked(roads, dataset.ROADS_SCHEMA, out / dataset.ROADS_FILE)
    write_checked(episodes, REAL_EPISODES_SCHEMA, out / REAL_EPISODES_FILE)
    write_checked(roads, REAL_ROADS_SCHEMA, out / REAL_ROADS_FILE)
    write_checked(pd.concat(run_frames, ignore_index=True), TICKS_SCHEMA, out / TICKS_FILE)
    write_checked(
        pd.concat(kin_frames, ignore_index=True), dataset.KINEMATICS_SCHEMA, out / dataset.KINEMATICS_FILE
    )
    command = ["trustroute", "import", "carla-logs", str(source), "--out", str(out)]
    manifest = {
        "study": "carla-real-study",
        "config_path": None,
        "config_hash": None,
        "command": command,
        "planned_episodes": int(len(episodes)),
        "finished_episodes": int(len(episodes)),
        "seeds": {},
        "run": {"importer": __name__, "tick_seconds": TICK_SECONDS},
        "engine": dataset.CARLA_LOGS_ENGINE,
        "config": {
            "name": "carla-real-study",
            "town": None,
            "driver_model": None,
            "specs": [str(PACKAGED_SPECS / name) for name in IMPORTED_SPECS],
            # what the specs were, for an analysis where these paths are gone (inputs.py, `found_spec`)
            SPEC_SHA256: [sha256_of(PACKAGED_SPECS / name) for name in IMPORTED_SPECS],
            "conditions": ["aware", "free"],
            "report_every": 1,
        },
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "git_revision": git_revision(),
        "packages": package_versions(),
        "source": str(source),
        "files": {
            "episodes": dataset.EPISODES_FILE,
            "roads": dataset.ROADS_FILE,
            "kinematics": dataset.KINEMATICS_FILE,
            "real_episodes": REAL_EPISODES_FILE,
            "real_roads": REAL_ROADS_FILE,
            "ticks": TICKS_FILE,
        },
        "failed_episodes": [],
        "expected": {},
        "real_study": {
            "attribution": "Logs of the CARLA study of Yu, Dong, Sheng, Feng, Kwiatkowska (ICRA 2024), "
            "released in shuyang-dong/trust_aware_hrc_carla_sim under the MIT licence, "
            "Copyright (c) 2025 Shuyang Dong.",
            "participants": sorted(int(p) for p in episodes["participant"].unique()),
            "inventory": inventory,
            "missing_sessions": missing,
            "authors_subsets": authors_subsets(source),
            "arrival_radius_m": ARRIVAL_RADIUS_M,
            "max_distance_to_spawn_point_m": round(worst_distance, 2),
            "kinematics_every_ticks": KINEMATICS_EVERY,
        },
    }
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1, default=str))
    return manifest


def _logged_satisfaction(episodes: pd.DataFrame, roads: pd.DataFrame, town, driver_model) -> np.ndarray:
    """The episode's `satisfied`: its spec on the belief the AV logged (what the AV saw)."""
    specs = {Path(name).stem: load_spec(PACKAGED_SPECS / name, town) for name in IMPORTED_SPECS}
    sat = satisfaction_by_source(episodes, roads, specs, town, driver_model.trust_levels)
    return sat["satisfied_logged"].fillna(False).to_numpy(dtype=bool)


def write_checked(frame: pd.DataFrame, schema: pa.Schema, path: Path) -> None:
    """`frame`'s columns of `schema`, checked (trustroute.core.dataset) and written atomically."""
    table = dataset.table_from_frame(frame.reset_index(drop=True), schema)
    temporary = path.with_name(f".tmp-{path.name}")
    dataset.write_table(table, temporary)
    temporary.replace(path)
