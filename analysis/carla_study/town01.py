"""The authors' CARLA Town01 tables, as one packaged JSON file: road states, arrival points,
trials, preset baseline routes, shortest-route tables, road incidents and belief grids.

`build_carla_tables(checkout)` derives the file from a checkout of the authors' repository
(shuyang-dong/trust_aware_hrc_carla_sim, MIT); it is run once by a maintainer and its output is
committed as analysis/data/real_study/town01.json. `load_carla_tables()` reads the committed file,
so importing logs never needs the checkout's code or pickles. docs/real_study.md explains every
table and the evidence for it.
"""

from __future__ import annotations

import json
import pickle
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.core.errors import InputError
from trustroute.networks.road import Road
from trustroute.networks.road_geometry import polyline_length

TABLES_PATH = Path(__file__).resolve().parents[1] / "data" / "real_study" / "town01.json"
# Their incident names -> the project's (networks/town.py INCIDENT_TYPES).
INCIDENT_NAMES = {"construction": "obstacle", "pedestrian": "pedestrian", "truck": "truck", "empty": "none"}
# Trial -> (start state, goal junction, project spec); from the driver script's World.__init__
# (start states), the policy scripts' goal_set, and the README (trial 3 is the warm-up route).
TRIALS = {
    1: {"start": "A3", "goal": "L", "spec": "phi1", "warmup": False},
    2: {"start": "H3", "goal": "E", "spec": "phi2", "warmup": False},
    3: {"start": "I3", "goal": "F", "spec": None, "warmup": True},
}
ARRIVAL_RADIUS_M = 15.0  # World.if_reach_location(distance_threshold=15.0) in the driver script


@dataclass(frozen=True)
class CarlaTables:
    """The packaged tables. A state "A1" is the authors' name of the directed road F-A."""

    road_of_state: dict[str, str]
    state_of_road: dict[str, str]
    arrival_point: dict[str, tuple[float, float]]  # state -> (x, y) the simulator tested
    trials: dict[int, dict]
    baseline_routes: dict[int, list[str]]  # trial -> states after the start state
    shortest_routes: dict[int, dict[str, list[str]]]  # trial -> state -> states to the goal
    incidents: dict[str, str]  # directed road -> project incident name
    belief_points: dict[int, np.ndarray]  # trial -> [n, 7] the policy's belief grid
    spawn_points: np.ndarray  # [n, 2] all Town01 spawn points (x, y)
    source: str

    def successors(self, state: str) -> list[str]:
        """States reachable from `state` at its junction: the town's moves, plus staying at the
        goal (the policy's self-loop action a3 at the goal's roads)."""
        came_from, at = Road.parse(self.road_of_state[state])
        out = [
            s
            for s, road in self.road_of_state.items()
            if Road.parse(road).from_junction == at and Road.parse(road).to_junction != came_from
        ]
        return sorted(out)


def load_carla_tables(path: Path | None = None) -> CarlaTables:
    path = Path(path) if path is not None else TABLES_PATH
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(
            str(path),
            "",
            f"cannot read the CARLA tables ({exc})",
            "reinstall trustroute or rebuild the file with build_carla_tables",
        ) from None
    states = data["states"]
    return CarlaTables(
        road_of_state={s: v["road"] for s, v in states.items()},
        state_of_road={v["road"]: s for s, v in states.items()},
        arrival_point={s: (float(v["arrival"][0]), float(v["arrival"][1])) for s, v in states.items()},
        trials={int(k): v for k, v in data["trials"].items()},
        baseline_routes={int(k): list(v) for k, v in data["baseline_routes"].items()},
        shortest_routes={
            int(k): {s: list(r) for s, r in v.items()} for k, v in data["shortest_routes"].items()
        },
        incidents=dict(data["incidents"]),
        belief_points={int(k): np.asarray(v, dtype=float) for k, v in data["belief_points"].items()},
        spawn_points=np.asarray(data["spawn_points"], dtype=float),
        source=data["source"],
    )


# -- building the file from a checkout (maintainer step) -----------------------------------
def _state_table(checkout: Path) -> pd.DataFrame:
    spawn = pd.read_csv(checkout / "spawn_point_list.csv", index_col=0)
    states = pd.read_csv(checkout / "state_route_info" / "state_location.csv")
    pair = states["last_current_junc"].str.strip("()").str.split(",")
    states["road"] = pair.map(lambda p: Road(p[0].strip(), p[1].strip()).id)
    index = states["destination_spawnpoint_index"].to_numpy()
    states["x"] = spawn.loc[index, "x"].to_numpy() + states["delta_x"].to_numpy()
    states["y"] = spawn.loc[index, "y"].to_numpy() + states["delta_y"].to_numpy()
    return states


def _baseline_routes(script: str) -> dict[int, list[str]]:
    """The preset routes of World.set_route_baseline: state names in order, per trial branch."""
    body = script[script.index("def set_route_baseline") : script.index("def set_shortest_route")]
    routes: dict[int, list[str]] = {}
    for match in re.finditer(r"trial_id\s*==\s*(\d)(.*?)(?=elif self\.trial_id|else:)", body, re.S):
        code = "\n".join(line for line in match.group(2).splitlines() if not line.strip().startswith("#"))
        routes[int(match.group(1))] = re.findall(r"\(\('([A-L]\d)'", code)
    return routes


def _incidents(policy_script: str, road_of_state: dict[str, str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for a, b, name in re.findall(r"\('([A-L]\d)', '([A-L]\d)'\): '(\w+)'", policy_script):
        if a == b:
            continue  # the goal self-loop, not a road
        road = Road(Road.parse(road_of_state[a]).to_junction, Road.parse(road_of_state[b]).to_junction).id
        if road_of_state[b] != road:
            raise ValueError(f"edge {a}->{b} does not enter {b} from {a}'s junction")
        previous = out.setdefault(road, INCIDENT_NAMES[name])
        if previous != INCIDENT_NAMES[name]:
            raise ValueError(f"road {road} has two incidents in {policy_script[:40]}")
    return out


def build_carla_tables(checkout: Path) -> dict:
    """Derive the tables from a checkout of the authors' repository (reads their robot_nodes.pkl
    belief grids with pickle: run it only on a checkout you trust)."""
    checkout = Path(checkout)
    states = _state_table(checkout)
    road_of_state = dict(zip(states["state"], states["road"], strict=True))
    script = (checkout / "manual_control_steeringwheel_trust_aware_hrc_fix_route.py").read_text()
    shortest = {}
    for trial in TRIALS:
        table = pd.read_csv(checkout / "state_route_info" / f"shortest_route_trial_{trial}.csv")
        shortest[trial] = {
            row.current_state: [s for s in str(row.shortest_route).split(",") if s != "-1"]
            for row in table.itertuples()
        }
    incidents = _incidents((checkout / "policy" / "policy_retrieve_trial1.py").read_text(), road_of_state)
    beliefs = {}
    for trial in (1, 2, 3):
        with open(checkout / "policy" / f"pickle_data_trial{trial}_v2" / "robot_nodes.pkl", "rb") as f:
            nodes = pickle.load(f)  # noqa: S301 - the authors' data file, read by a maintainer
        beliefs[trial] = sorted({tuple(float(v) for v in key[1]) for key in nodes})
    spawn = pd.read_csv(checkout / "spawn_point_list.csv", index_col=0)
    return {
        "source": "Derived from shuyang-dong/trust_aware_hrc_carla_sim (MIT, Copyright (c) 2025 "
        "Shuyang Dong): state_route_info/state_location.csv, spawn_point_list.csv, "
        "state_route_info/shortest_route_trial_*.csv, policy/policy_retrieve_trial1.py (incidents), "
        "policy/pickle_data_trial*_v2/robot_nodes.pkl (belief grids), "
        "manual_control_steeringwheel_trust_aware_hrc_fix_route.py (start states, baseline routes). "
        "See docs/real_study.md.",
        "arrival_radius_m": ARRIVAL_RADIUS_M,
        "states": {
            row.state: {
                "road": row.road,
                "arrival_spawn_point": int(row.destination_spawnpoint_index),
                "arrival": [round(float(row.x), 4), round(float(row.y), 4)],
            }
            for row in states.itertuples()
        },
        "trials": {str(k): v for k, v in TRIALS.items()},
        "baseline_routes": {str(k): v for k, v in _baseline_routes(script).items()},
        "shortest_routes": {str(k): v for k, v in shortest.items()},
        "incidents": dict(sorted(incidents.items())),
        "belief_points": {str(k): v for k, v in beliefs.items()},
        "spawn_points": [[round(float(x), 3), round(float(y), 3)] for x, y in spawn[["x", "y"]].to_numpy()],
    }


def write_carla_tables(checkout: Path, path: Path | None = None) -> Path:
    path = Path(path) if path is not None else TABLES_PATH
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(build_carla_tables(checkout), indent=1) + "\n")
    return path


# -- road shapes and lengths ------------------------------------------------------------------
# Town01's roads A-E and H-L run along its outer west and east streets: their arrival points (and
# those of E-A, L-H) lie beyond both of their junctions, on the outer side, and Town01's spawn
# points line the outer streets at x = 0 and x = 394 m (docs/real_study.md). The other roads are
# straight streets between their junctions.
OUTER_ROADS = {("A", "E"): "west", ("H", "L"): "east"}
# Spawn points within this many metres of the town's outermost one on a side are the lanes of
# that side's street (Town01's lanes are 3.5 m apart; its next street inward is 60 m away).
STREET_BAND_M = 6.0


def outer_streets(tables: CarlaTables) -> dict[str, float]:
    """The centre lines of Town01's four outer streets, in CARLA's frame: x of the west and east
    streets, y of the north and south ones (CARLA's y grows southwards). Each is the middle of the
    spawn points within STREET_BAND_M of the outermost spawn point on that side (one per lane)."""
    points = tables.spawn_points

    def middle(values: np.ndarray, outermost: float) -> float:
        band = values[np.abs(values - outermost) <= STREET_BAND_M]
        return float((band.min() + band.max()) / 2)

    xs, ys = points[:, 0], points[:, 1]
    return {"west": middle(xs, xs.min()), "east": middle(xs, xs.max()),
            "north": middle(ys, ys.min()), "south": middle(ys, ys.max())}


def _outer_shape(u: tuple[float, float], v: tuple[float, float], side_x: float,
                 streets: dict[str, float]) -> list[tuple[float, float]]:
    """From junction u out along its east-west street to the outer street at x = side_x, along it
    to v's east-west street and in to v (town frame: y is CARLA's y negated). Corners are drawn
    sharp at the crossings of the streets' centre lines."""
    def street_y(junction: tuple[float, float]) -> float:
        carla_y = -junction[1]
        nearer = min(("north", "south"), key=lambda name: abs(streets[name] - carla_y))
        return -streets[nearer]

    return [u, (side_x, street_y(u)), (side_x, street_y(v)), v]


def town01_geometry(tables: CarlaTables, junctions: dict[str, list[float]]) -> dict[str, dict]:
    """Shape and length of every directed road of Town01 (town frame, metres, 2 and 3 decimals):
    the outer roads along the outer streets (OUTER_ROADS), the others straight between junctions."""
    streets = outer_streets(tables)
    geometry: dict[str, dict] = {}
    for road in sorted(set(tables.road_of_state.values())):
        u, v = Road.parse(road)
        a = (float(junctions[u][0]), float(junctions[u][1]))
        b = (float(junctions[v][0]), float(junctions[v][1]))
        side = OUTER_ROADS.get((u, v)) or OUTER_ROADS.get((v, u))
        shape = [a, b] if side is None else _outer_shape(a, b, streets[side], streets)
        shape = [(round(float(x), 2), round(float(y), 2)) for x, y in shape]
        geometry[road] = {"shape": [list(p) for p in shape], "length": round(polyline_length(shape), 3)}
    return geometry


TOWN01_SOURCE = (
    "Town01 geometry of the CARLA study of Yu et al., ICRA 2024 (12 junctions A-L, 18 two-way roads): "
    "junction coordinates are the mean of the three arrival points of the roads entering the junction "
    "(state_route_info/state_location.csv with spawn_point_list.csv of "
    "shuyang-dong/trust_aware_hrc_carla_sim, MIT), in metres, CARLA y negated (CARLA's frame is "
    "left-handed); roads are the directed roads of state_location.csv, incidents those of "
    "policy/policy_retrieve_trial1.py; road shapes and lengths: A-E and H-L along the outer west and "
    "east streets located by the spawn points, the other roads straight. Built by "
    "trustroute.analysis.carla_study.town01.town01_town_dict; networks/data/PROVENANCE.md, "
    "docs/real_study.md."
)


def town01_town_dict(tables: CarlaTables) -> dict:
    """The town file (networks/town.py schema) of Town01, from the authors' tables alone: the roads of
    their state table, the incidents of their policy script, and junction coordinates that are the
    mean of the arrival points of the three roads entering each junction, y negated (CARLA's frame
    is left-handed; the town's plane is right-handed), and each road's shape and length
    (`town01_geometry`). The packaged default town is this output."""
    points: dict[str, list[tuple[float, float]]] = {}
    for state, road in tables.road_of_state.items():
        points.setdefault(Road.parse(road).to_junction, []).append(tables.arrival_point[state])
    centres = {j: np.mean(np.asarray(p), axis=0) for j, p in sorted(points.items())}
    roads = sorted({tuple(sorted(Road.parse(road))) for road in tables.road_of_state.values()})
    junctions = {j: [round(float(c[0]), 2), round(float(-c[1]), 2)] for j, c in centres.items()}
    return {
        "junctions": junctions,
        "roads": [list(r) for r in roads],
        "incidents": dict(sorted(tables.incidents.items())),
        "geometry": town01_geometry(tables, junctions),
        "source": TOWN01_SOURCE,
    }
