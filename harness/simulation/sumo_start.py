"""Starting, reusing and closing SUMO: the one place that builds the command line (every option in
one list).

libsumo runs one simulation per process. Starting it parses the net, most of a short episode's
cost, so `sumo_session` keeps the simulation open between episodes that run on the same command
line and returns it to the empty state it had right after its start (`simulation.loadState` of a
snapshot saved then: time 0, no vehicles, persons, routes or types, traffic lights as started).
This is exact because nothing SUMO draws from its own random streams reaches an episode: the
trustroute vehicles drive without imperfection or speed deviation or stand parked, a pedestrian's
speed is set by its scene, and the striping model's dawdling is off (`--pedestrian.striping.dawdling
0`); every random draw of an episode comes from its seeded Generator. tests/harness/simulation/
test_sumo_reuse.py checks that an episode's tables are the same with another SUMO seed and in a
reused simulation as in a fresh one. Runs where SUMO's own draws do matter (background traffic,
route files) and runs with outputs or a GUI start SUMO afresh, seeded with the episode's seed, and
close it at the end. One episode at a time holds the process's simulation: a second started while
one runs is refused (`SimulationInUse`) rather than reloaded under it. Nothing happens at import
time (libsumo itself is imported when a simulation starts).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Protocol, TypeVar

from trustroute.core import ranges
from trustroute.core.errors import InputError
from trustroute.harness.simulation.performance import DEFAULT_LIMITS, PerformanceLimits
from trustroute.networks.sumo_import import require_net_file
from trustroute.networks.sumo_net import find_binary

T = TypeVar("T")


@dataclass(frozen=True)
class SumoConfig:
    """Simulation settings of an episode.

    performance_limits: where `succ` ends, per incident kind (harness/simulation/performance.py).
    background_vehicles: seeded background traffic, vehicles kept on the net (0: none), in
    ranges.BACKGROUND_VEHICLES (the range every door takes); a refusal names the keyword the
    API's caller wrote.
    """

    step_length: float = 0.5        # seconds: large steps keep episodes fast, 0.5 s keeps yielding sane
    max_sim_seconds: float = 7200.0  # the sim-time cap: SimTimeCapReached, a bug or a jam (background.py)
    performance_limits: Mapping[str, PerformanceLimits] = field(default_factory=lambda: dict(DEFAULT_LIMITS))
    background_vehicles: int = 0
    gui: bool = False               # run in sumo-gui through TraCI (needs a display) instead of libsumo
    output_dir: str | None = None   # also write SUMO's own FCD and route outputs here (sumo_files.py)
    route_files: tuple[str, ...] = ()   # background traffic SUMO loads with the net (background.py)

    def __post_init__(self) -> None:
        object.__setattr__(self, "background_vehicles", ranges.BACKGROUND_VEHICLES.check_as(
            self.background_vehicles, "background_vehicles", where=ranges.BACKGROUND_KEYWORD))


class Sumo(Protocol):
    """The SUMO API a simulation is driven through: the libsumo module, or traci with its constants
    (`_TraciWithConstants`, sumo-gui). Neither ships type information, so each domain is Any; the
    protocol names the domains and constants the harness uses."""

    vehicle: Any
    vehicletype: Any
    person: Any
    lane: Any
    edge: Any
    junction: Any
    route: Any
    simulation: Any
    TraCIException: type[Exception]
    VAR_LANEPOSITION: int
    VAR_POSITION: int
    VAR_SPEED: int
    VAR_ACCELERATION: int
    VAR_LANE_ID: int
    VAR_LEADER: int
    VAR_ANGLE: int

    def start(self, cmd: list[str]) -> object: ...

    def simulationStep(self, step: float = 0.0) -> object: ...

    def close(self) -> None: ...


@lru_cache(maxsize=1)
def sumo_binary() -> str:
    """The sumo binary of the eclipse-sumo wheel (libsumo needs its installation, not the process)."""
    return find_binary("sumo")


def sumo_command(net_path: Path, seed: int, config: SumoConfig) -> list[str]:
    """The whole SUMO command line of an episode."""
    return [
        sumo_binary(),
        "--net-file", str(net_path),
        "--seed", str(int(seed)),
        "--step-length", f"{config.step_length:g}",
        "--time-to-teleport", "-1",             # never teleport: a stuck ego must show up as stuck
        "--collision.action", "warn",           # collisions are logged and measured, never fatal
        "--collision.check-junctions", "true",  # pedestrians on crossings are inside junctions
        "--collision.mingap-factor", "0",       # a collision is a real overlap, not a minGap breach
        "--pedestrian.model", "striping",
        "--pedestrian.striping.dawdling", "0",  # a pedestrian walks at the speed its scene sets
        "--default.action-step-length", f"{config.step_length:g}",
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--duration-log.disable", "true",
        "--verbose", "false",
        *native_output_options(config),
        *route_file_options(config),
    ]


def route_file_options(config: SumoConfig) -> list[str]:
    """The background traffic's route files; a trip SUMO cannot route is left out, not fatal."""
    if not config.route_files:
        return []
    return ["--route-files", ",".join(config.route_files), "--ignore-route-errors", "true"]


def native_output_options(config: SumoConfig) -> list[str]:
    """SUMO's FCD (every vehicle and person per step) and vehroute outputs, when output_dir is set."""
    if config.output_dir is None:
        return []
    folder = Path(config.output_dir)
    return [
        "--fcd-output", str(folder / "fcd.xml"),
        "--vehroute-output", str(folder / "routes.rou.xml"),
        "--vehroute-output.last-route", "true",        # the ego's route as finally extended
        "--vehroute-output.write-unfinished", "true",  # vehicles still driving when the episode ends
        "--vehroute-output.exit-times", "true",
    ]


def _libsumo() -> Sumo:
    import libsumo

    return libsumo


class _TraciWithConstants:
    """traci with its constants as attributes, like libsumo (the episode code uses `sumo.VAR_...`)."""

    def __init__(self) -> None:
        import traci

        self._traci = traci

    def __getattr__(self, name: str) -> Any:   # a traci attribute or constant: untyped
        try:
            return getattr(self._traci, name)
        except AttributeError:
            return getattr(self._traci.constants, name)


def check_display() -> None:
    """sumo-gui needs an X display: a one-line error when there is none."""
    import os

    if not os.environ.get("DISPLAY"):
        raise InputError("--gui", "", "no display (DISPLAY is not set), so sumo-gui cannot open a window",
                         "run on a machine with a display, under xvfb-run, or drop --gui and open the "
                         "--rrd recording in the Rerun web viewer")


@dataclass(frozen=True)
class HotCalls:
    """The calls an episode makes every step (the step, the subscription, the collision count)
    and its clock (read once per `advance`, then counted in steps), bound once per episode."""

    step: Callable[[], object]
    time: Callable[[], float]
    subscription_results: Callable[[str], dict]
    colliding_number: Callable[[], int]


def hot_calls(sumo: Sumo) -> HotCalls:
    """The per-step calls as libsumo's native functions: its Python wrappers (a staticmethod per
    call, and simulationStep's step-listener pass, which episodes do not use) cost a Python frame
    each, about 500 per episode. With TraCI (sumo-gui) or a traced libsumo, the public API."""
    native = getattr(getattr(sumo, "libsumo", None), "_libsumo", None)
    # libsumo.start(traceFile=...) wraps its step for tracing: then keep the public calls.
    traced = getattr(getattr(sumo, "_libsumo_step", None), "__qualname__", "") != "simulation.step"
    if native is None or traced:
        return HotCalls(sumo.simulationStep, sumo.simulation.getTime, sumo.vehicle.getSubscriptionResults,
                        sumo.simulation.getCollidingVehiclesNumber)
    return HotCalls(native.simulation_step, native.simulation_getTime, native.vehicle_getSubscriptionResults,
                    native.simulation_getCollidingVehiclesNumber)


def reusable(config: SumoConfig) -> bool:
    """Whether an episode on `config` may run in a simulation kept open from an earlier episode:
    not when SUMO's own random draws reach it (background vehicles dawdle, route files' vehicles
    draw their speeds), nor with SUMO's output files or a GUI, which belong to one run."""
    return (not config.gui and config.output_dir is None and not config.route_files
            and config.background_vehicles == 0)


@dataclass(frozen=True)
class _OpenSimulation:
    """The libsumo simulation this process keeps open: what it was started on (the command line
    without the seed, and the net file's identity), and the snapshot of its empty state right
    after the start."""

    started_on: tuple
    snapshot: Path


_open: list[_OpenSimulation] = []   # at most one: libsumo runs one simulation per process
# Facts of the running simulation's net (a lane's length, its links, a crossing's path), read
# from SUMO once per start (`net_fact`): returning to the snapshot (loadState) never changes the
# net, so episodes in one simulation share them. Every start and close forgets them (code that
# starts libsumo itself calls close_simulation first).
_NET_FACTS: dict[tuple, Any] = {}
_closes_at_exit: list[int] = []     # the pid whose exit closes it (close_at_exit)
_in_use: list[int] = []             # the pid of a process whose simulation an episode is driving


class SimulationInUse(RuntimeError):
    """A second episode asked for the process's one SUMO simulation while another drives it."""


@contextlib.contextmanager
def _one_user() -> Iterator[None]:
    """Hold the process's simulation for one episode. libsumo runs one simulation per process: a
    second episode started while one is running (two gym environments, run_episode during a gym
    episode) would load its own start under the first one, so it is refused here instead. Keyed by
    pid, so a process forked while an episode runs holds nothing."""
    if os.getpid() in _in_use:
        raise SimulationInUse(
            "libsumo runs one SUMO simulation per process, and another episode of this process is "
            "driving it (a TrustRouting environment or run_episode with engine=\"sumo\" not yet "
            "finished or closed): finish or close that episode first, run each SUMO environment in "
            "its own process (e.g. gymnasium.vector.AsyncVectorEnv), or use engine=\"model\"")
    _in_use.append(os.getpid())
    try:
        yield
    finally:
        _in_use.remove(os.getpid())


def _net_file(net_path: Path) -> os.stat_result:
    """The net file's status, read once per session: it is a file (`require_net_file`'s one-line
    error otherwise) and its identity (`_started_on`) in one system call, not two."""
    try:
        found = os.stat(net_path)
        if stat.S_ISREG(found.st_mode):
            return found
    except (OSError, ValueError):
        pass
    require_net_file(net_path)   # not a file: the error that says so
    return os.stat(net_path)     # (it became one in between)


def _started_on(command: list[str], net: os.stat_result) -> tuple:
    """The command line without its seed, and the net file's identity (`net`, its status): a net
    rewritten in place (a town imported again into the same folder) is another simulation."""
    at = command.index("--seed")
    return (*command[:at], *command[at + 2:], net.st_ino, net.st_size, net.st_mtime_ns)


def net_fact(key: tuple, read: Callable[[], T]) -> T:
    """What `read()` gives, asked of SUMO once per started simulation: a fact of its net that no
    episode changes, named by `key` (what is read, and of which lane or road)."""
    if key in _NET_FACTS:
        return _NET_FACTS[key]
    value = _NET_FACTS[key] = read()
    return value


def close_simulation() -> None:
    """Close the simulation kept open between episodes, if any (also run at the process's exit).
    Code that starts libsumo itself calls this first."""
    _NET_FACTS.clear()
    while _open:
        simulation = _open.pop()
        with contextlib.suppress(Exception):
            _libsumo().close()
        shutil.rmtree(simulation.snapshot.parent, ignore_errors=True)


def _close_at_exit() -> None:
    """Close this process's simulation, and remove its snapshot, when the process exits (once per
    process). A forked child (a study's worker) forgets the parent's simulation: it starts its own,
    and its exit leaves the parent's snapshot alone."""
    from multiprocessing import util

    if not _closes_at_exit:   # the hook is inherited by every process forked from here on
        os.register_at_fork(after_in_child=_open.clear)
    if _closes_at_exit != [os.getpid()]:
        # multiprocessing's exit (its workers end with os._exit) runs these finalizers, atexit does not
        util.Finalize(None, close_simulation, exitpriority=10)
        _closes_at_exit[:] = [os.getpid()]


def _start(sumo: Sumo, command: list[str], net_path: Path, config: SumoConfig) -> None:
    """Start SUMO on `command`; an unreadable net or an unusable SUMO installation is an InputError."""
    _NET_FACTS.clear()
    try:
        sumo.start(command)
    except Exception as exc:  # libsumo raises its own TraCIException / FatalTraCIError types
        with contextlib.suppress(Exception):
            sumo.close()
        message = str(exc).strip().splitlines()
        if config.route_files:
            raise InputError(str(net_path), "", "SUMO cannot load the net with the route files "
                             f"{', '.join(config.route_files)}" + (f" ({message[-1]})" if message else ""),
                             "pass route files that define every vehicle type they use, types first"
                             ) from None
        raise InputError(str(net_path), "", "SUMO cannot load the net"
                         + (f" ({message[-1]})" if message else ""),
                         "rebuild it with `trustroute net build` (delete the cached file)") from None


def _empty_simulation(command: list[str], net_path: Path, net: os.stat_result, config: SumoConfig) -> Sumo:
    """libsumo in the empty state of `command`'s start: the open simulation returned to its
    snapshot when it runs the same command line (the seed aside) on the same net file (`net`, its
    status), else a fresh start."""
    sumo = _libsumo()
    key = _started_on(command, net)
    if _open and _open[0].started_on == key:
        with contextlib.suppress(Exception):   # a snapshot that no longer loads: start afresh below
            sumo.simulation.loadState(str(_open[0].snapshot))
            return sumo
    close_simulation()
    _start(sumo, command, Path(net_path), config)
    folder = Path(tempfile.mkdtemp(prefix="trustroute-sumo-"))
    snapshot = folder / "empty.state.xml"
    sumo.simulation.saveState(str(snapshot))
    _close_at_exit()
    _open.append(_OpenSimulation(key, snapshot))
    return sumo


@contextlib.contextmanager
def sumo_session(net_path: Path, seed: int, config: SumoConfig) -> Iterator[Sumo]:
    """libsumo on `net_path` in its empty state at time 0, for one episode.

    A reusable run (`reusable`) gets the simulation kept open from the process's last episode,
    returned to its snapshot, and leaves it open; an episode that raises closes it. Other runs
    get `fresh_session`. An unreadable net or an unusable SUMO installation is an InputError (one
    line, exit 2).
    """
    if not reusable(config):
        with fresh_session(net_path, seed, config) as sumo:
            yield sumo
        return
    net = _net_file(net_path)
    with _one_user():
        sumo = _empty_simulation(sumo_command(net_path, seed, config), net_path, net, config)
        try:
            yield sumo
        except BaseException:
            close_simulation()   # whatever the episode left behind goes with it
            raise


@contextlib.contextmanager
def fresh_session(net_path: Path, seed: int, config: SumoConfig) -> Iterator[Sumo]:
    """SUMO started on `net_path` with `seed` and closed at the end (the simulation kept open
    between episodes is closed first): runs whose SUMO draws matter, with outputs or a GUI, and
    the benchmarks' bare loops."""
    require_net_file(net_path)
    with _one_user():
        close_simulation()
        command = sumo_command(net_path, seed, config)
        sumo: Sumo
        if config.gui:
            check_display()
            # sumo-gui starts running at once and closes at the end; same options as the libsumo run.
            command = [find_binary("sumo-gui"), *command[1:], "--start", "true", "--quit-on-end", "true"]
            sumo = _TraciWithConstants()
        else:
            sumo = _libsumo()
        _start(sumo, command, Path(net_path), config)
        try:
            yield sumo
        finally:
            _NET_FACTS.clear()
            sumo.close()

