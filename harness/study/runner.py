"""Running a study: plan, skip what is done, run the rest on a backend, consolidate.

One worker function, `run_unit(study_dir, context, unit)`, runs a unit of episodes and writes their
parts; it never raises (an error comes back as a failed `EpisodeOutcome`). A unit is one episode
(`run_task`: its own part), or on the model engine a batch of consecutive episodes (`run_batch`:
one batch part, harness/study/parts.py), since a model-engine episode takes about a millisecond
and a part file per episode would cost more than the episode. Retries run episode by episode,
so an episode that fails a batch (or whose worker died with it) is isolated on its retry. Three
backends hand it units: in-process (`workers=1`), a local process pool (`workers=N`), and Dask distributed
(`scheduler="ADDRESS"`, or `scheduler="local"` for a local Dask cluster). The study's context
(town, specs, policies, participants' driver models: harness/study/context.py) is built once,
by `validate_study` before any worker starts, and handed to `run_unit`: the pool's workers are
forked after it and inherit it, a Dask cluster gets one copy per worker (scattered before the
tasks), so nothing large travels with the tasks and the result cannot depend on the backend. The
consolidation is given the same context (the expected values, the inputs it stores). A failed
episode (an error, or its worker process dying) is retried up to `attempts - 1` times (default:
once), unless the episode itself failed on bad input (an InputError, e.g. a town jammed by its
background traffic: the same seed fails the same way again); if it still fails, every attempt's
reason is recorded in failures/ and the study goes on. A rerun resumes: valid parts are skipped,
damaged parts re-run.

Nothing is written before every input has validated (town, driver model, specs, policies,
population: `study_context`) and the output directory is known to be writable and new, empty or
this study's (a folder of other files is refused: harness/study/resume.py); the directory is
marked as the study's before anything else is written in it (`open_study_dir`), then locked
(`study.lock`, fcntl.flock) for the whole run, so a second run on it is refused with the holder's
pid, host and start time. The local pool is harness/study/workers.py (workers that
die with the parent, a worker death failing only its own episode).
"""

from __future__ import annotations

import contextlib
import functools
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from trustroute.app.drivers import synthetic_driver
from trustroute.app.engines import ENGINES
from trustroute.core import defaults
from trustroute.core.dataset import LOCK_FILE
from trustroute.core.errors import InputError
from trustroute.core.interrupts import sigterm_raises
from trustroute.core.progress import bar_disable
from trustroute.core.ranges import ATTEMPTS
from trustroute.core.wording import counted, shown_value
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.context import StudyContext, study_context
from trustroute.harness.study.expected import expected_values, fallback_only_warnings
from trustroute.harness.study.manifest import DamagedParts, consolidate
from trustroute.harness.study.parts import sync_parts, write_batch_part, write_failure, write_part_tables
from trustroute.harness.study.plan import EpisodeTask, plan_episodes
from trustroute.harness.study.resume import (
    check_own_folder,
    check_study_folders,
    finished_episodes,
    mark_study_dir,
    recorded_config_hash,
)

if TYPE_CHECKING:
    from tqdm import tqdm

    from trustroute.harness.simulation.drivers import Driver, PersonControls
    from trustroute.harness.simulation.episode import EpisodeRecord
    from trustroute.harness.simulation.sumo_start import SumoConfig

BATCH_EPISODES = 250  # model-engine episodes per batch part (at most)
# Fewer episodes to run: one part each (a batch saves nothing there, and a damaged part costs one
# episode, not a batch)
BATCH_MIN_EPISODES = 1000
CONSOLIDATION_ROUNDS = 3
SYNC_EVERY = 64  # parts per file-system sync (harness/study/parts.py: sync_parts); for the model
# engine's batches, episodes of SYNC_EVERY full batches


@dataclass(frozen=True)
class EpisodeOutcome:
    episode_id: str
    ok: bool
    error: str = ""
    traceback: str = ""
    wall_seconds: float = 0.0
    # another attempt may end otherwise: not after the episode's own bad input (an InputError, such
    # as a TrafficJam), which the same seed meets again
    retry: bool = True


def failed_outcome(task: EpisodeTask, exc: Exception, started: float, in_episode: bool) -> EpisodeOutcome:
    """The outcome of `task` failed by `exc`, `started` at its perf_counter time; `in_episode`: raised
    by the episode itself (then an InputError is not retried), else by the writing of its part."""
    return EpisodeOutcome(task.episode_id, False, f"{type(exc).__name__}: {exc}", traceback.format_exc(),
                          time.perf_counter() - started,
                          retry=not (in_episode and isinstance(exc, InputError)))


@dataclass(frozen=True)
class StudyRun:
    study_dir: Path
    planned: int
    skipped: int
    damaged: list[str]
    ran: int
    failed: list[str]
    retried: int
    seconds: float
    backend: str
    context: StudyContext | None = field(default=None, repr=False, compare=False)  # the one it ran with


def engine_function(engine: str) -> Callable:
    """The episode function of an engine (the registry's, trustroute/app/engines.py)."""
    return ENGINES[engine].run


RECORDINGS_DIR = "recordings"


def recording_path(study_dir: Path, episode_id: str) -> Path:
    """Where a study keeps the Rerun recording of an episode named in its config's `record`."""
    return Path(study_dir) / RECORDINGS_DIR / f"{episode_id}.rrd"


def run_planned_episode(context: StudyContext, task: EpisodeTask, rrd_path: Path | None = None,
                        sumo_config: SumoConfig | None = None, driver: Driver | None = None,
                        observer: Callable | None = None, person: PersonControls | None = None
                        ) -> EpisodeRecord:
    """Run the planned episode `task` of the study whose context is `context` exactly as the study
    runs it: the participant's driver model
    (population draw), the driver's Generator from the task's seed sequence (so the same initial trust
    and every later draw), SUMO's seed, the cell's setup and policy. Returns the EpisodeRecord.

    rrd_path, sumo_config (e.g. sumo-gui), observer and person apply to the SUMO engines only
    ("sumo", and "live", where `driver` is the remote person of harness/live in place of the
    synthetic driver and `person` their controls at the wheel)."""
    config = context.config
    engine = ENGINES[config.engine]
    if driver is None:
        driver = synthetic_driver(context.driver_model(task.participant), task.driver_rng(),
                                  report_accuracy=config.report_accuracy)
    setup, policy = context.setup(task.spec, task.condition), context.policies[(task.spec, task.condition)]
    run = engine_function(config.engine)
    if not engine.drives_sumo:
        return run(setup, policy, driver, task.episode_id, task.seed)
    from trustroute.harness.simulation.episode import EpisodeOptions
    from trustroute.harness.simulation.sumo_start import SumoConfig

    sumo_config = replace(sumo_config if sumo_config is not None else SumoConfig(),
                          background_vehicles=config.background_vehicles,
                          route_files=tuple(config.routes))
    options = EpisodeOptions(config=sumo_config, observer=observer, person=person, rrd_path=rrd_path)
    return run(setup, policy, driver, task.episode_id, task.seed, options)


def run_task(context: StudyContext, study_dir: str, task: EpisodeTask) -> EpisodeOutcome:
    """Run one episode and write its part. Never raises: errors come back in the outcome."""
    started = time.perf_counter()
    try:
        recorded = task.episode_id in context.config.record
        rrd = recording_path(Path(study_dir), task.episode_id) if recorded else None
        record = run_planned_episode(context, task, rrd_path=rrd)
    except Exception as exc:  # one bad episode must never stop the study
        return failed_outcome(task, exc, started, in_episode=True)
    try:
        write_part_tables(Path(study_dir), task, record.summary, record.tables())
    except Exception as exc:
        return failed_outcome(task, exc, started, in_episode=False)
    return EpisodeOutcome(task.episode_id, True, wall_seconds=time.perf_counter() - started)


def run_batch(context: StudyContext, study_dir: str, tasks: tuple[EpisodeTask, ...]) -> list[EpisodeOutcome]:
    """Run model-engine episodes one after the other, exactly as `run_task` runs each, and write
    the ones that finished as one batch part. Never raises: errors come back in the outcomes."""

    outcomes: list[EpisodeOutcome] = []
    done: list[tuple[EpisodeTask, dict, dict]] = []
    for task in tasks:
        started = time.perf_counter()
        try:
            record = run_planned_episode(context, task)
            done.append((task, record.summary, record.tables()))
            outcomes.append(EpisodeOutcome(task.episode_id, True, wall_seconds=time.perf_counter() - started))
        except Exception as exc:  # one bad episode must never stop the others
            outcomes.append(failed_outcome(task, exc, started, in_episode=True))
    if done:
        started = time.perf_counter()
        try:
            write_batch_part(Path(study_dir), *(list(column) for column in zip(*done, strict=True)))
        except Exception as exc:  # nothing of the batch was stored: every episode of it failed
            return [failed_outcome(task, exc, started, in_episode=False) if outcome.ok else outcome
                    for task, outcome in zip(tasks, outcomes, strict=True)]
    return outcomes


Unit = tuple[EpisodeTask, ...]


def run_unit(study_dir: str, context: StudyContext, unit: Unit) -> list[EpisodeOutcome]:
    """A unit of work for the backends: one episode (its own part) or a batch (one batch part)."""
    if len(unit) == 1:
        return [run_task(context, study_dir, unit[0])]
    return run_batch(context, study_dir, unit)


def plan_units(config: StudyConfig, tasks: list[EpisodeTask], workers: int) -> list[Unit]:
    """The units of `tasks`: on the model engine, from BATCH_MIN_EPISODES episodes on, batches of
    consecutive episodes (at most BATCH_EPISODES, and enough batches to keep `workers` busy);
    otherwise one episode each."""
    if config.engine != "model" or len(tasks) < BATCH_MIN_EPISODES:
        return [(task,) for task in tasks]
    size = max(1, min(BATCH_EPISODES, -(-len(tasks) // max(1, 4 * workers))))
    return [tuple(tasks[i:i + size]) for i in range(0, len(tasks), size)]


def check_record_ids(config: StudyConfig, tasks: list[EpisodeTask]) -> None:
    """The config's `record` names planned episodes of a SUMO study, or InputError."""
    if not config.record:
        return
    if not ENGINES[config.engine].records:
        raise InputError(config.source_path, "study.record", "recordings need the SUMO engine",
                         'set engine = "sumo" or remove record')
    planned = {t.episode_id for t in tasks}
    unknown = [e for e in config.record if e not in planned]
    if unknown:
        raise InputError(config.source_path, "study.record",
                         f"{shown_value(unknown[0])} is not an episode of this study",
                         f"use ids like {tasks[0].episode_id!r} (p<participant>-<spec>-<condition>)")


# -- backends: each yields outcomes as they complete -------------------------------------------


UnitFunction = Callable[[StudyContext, Unit], list[EpisodeOutcome]]   # run_unit with the directory bound


def _serial(function: UnitFunction, context: StudyContext,
            tasks: list[Unit]) -> Iterator[list[EpisodeOutcome]]:
    for task in tasks:
        yield function(context, task)


def _process_pool(function: UnitFunction, context: StudyContext, tasks: list[Unit],
                  workers: int) -> Iterator[list[EpisodeOutcome]]:
    from trustroute.harness.study.workers import process_pool

    def died(unit: Unit, reason: str) -> list[EpisodeOutcome]:
        return [EpisodeOutcome(task.episode_id, False, f"worker died: {reason}") for task in unit]

    # forked workers inherit the context; spawned ones are sent it once each (workers.py)
    return process_pool(functools.partial(function, context), tasks, workers, died)


def _dask(function: UnitFunction, context: StudyContext, tasks: list[Unit], scheduler: str, workers: int,
          processes: bool) -> Iterator[list[EpisodeOutcome]]:
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(
            n_workers=max(1, workers), threads_per_worker=1, processes=processes, dashboard_address=None
        )
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout=10)
        except (OSError, ValueError, TypeError) as exc:
            raise InputError(
                "--scheduler",
                scheduler,
                f"cannot reach the Dask scheduler ({exc})",
                "start one with `dask scheduler` and pass its address, or use --scheduler local",
            ) from None
    try:
        shared = client.scatter(context, broadcast=True, hash=False)   # one copy per worker
        futures = {client.submit(function, shared, task, pure=False): task for task in tasks}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:
                yield [EpisodeOutcome(task.episode_id, False, f"dask: {type(exc).__name__}: {exc}")
                       for task in futures[future]]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _outcomes(
    function: UnitFunction, context: StudyContext, units: list[Unit], workers: int, scheduler: str | None,
    dask_processes: bool = True,
) -> Iterator[EpisodeOutcome]:
    if not units:
        return iter(())
    if scheduler is not None:
        batches = _dask(function, context, units, scheduler, workers, dask_processes)
    elif workers <= 1:
        batches = _serial(function, context, units)
    else:
        batches = _process_pool(function, context, units, min(workers, len(units)))
    return (outcome for batch in batches for outcome in batch)


def backend_name(workers: int, scheduler: str | None) -> str:
    if scheduler is not None:
        return f"dask ({scheduler})"
    return "in-process" if workers <= 1 else f"process pool ({workers} workers)"


# -- the study ---------------------------------------------------------------------------------


@contextlib.contextmanager
def study_lock(study_dir: Path) -> Iterator[None]:
    """Create the study directory (checked writable first) and hold its lock, or InputError naming
    the run that holds it."""
    check_study_output(study_dir)
    with held_study(study_dir, "wait for that run to finish (or stop it), or pass another --out"):
        yield


def held_study(study_dir: Path, fix: str) -> contextlib.AbstractContextManager[None]:
    """The study directory's lock, the one every command writing or reading the whole study holds
    (`study`, `live`, `withdraw`, `export`): taken at once or InputError naming the run that holds it
    and `fix`."""
    from trustroute.core.output_files import file_lock

    return file_lock(Path(study_dir) / LOCK_FILE, "study directory", wait=False, fix=fix)


@contextlib.contextmanager
def open_study_dir(study_dir: Path, config: StudyConfig) -> Iterator[None]:
    """Take the study directory for a run of `config`, the one way `trustroute study`, the API's
    `run_study` and `trustroute live` take it (after `check_before_writing`): marked as this
    study's before anything else is written in it (`mark_study_dir`), then locked (`study_lock`),
    then checked again under the lock (a run of another config that marked it first is refused)."""
    mark_study_dir(study_dir, config, config.content_hash)
    with study_lock(study_dir):
        mark_study_dir(study_dir, config, config.content_hash)
        yield


def check_study_output(study_dir: Path) -> None:
    """The study directory (--out) is a directory or can be made, outside any package: checked
    before any input is (a missing "aware" policy is synthesized then, which may take minutes) and
    before anything is said."""
    from trustroute.core.output_files import check_output_dir

    check_output_dir(study_dir, "--out", "study directory")   # (in a package too: read-only)


def validate_study(config: StudyConfig | StudyContext, scheduler: str | None = None,
                   attempts: int = defaults.ATTEMPTS, progress: bool = False) -> StudyContext:
    """Every input of the study, checked before anything is written: the engine, the town, driver
    model, specs, policies and population (building the context, synthesizing missing "aware"
    policies into the policy cache), the retry bound and the scheduler address. Returns the study's
    context: built here, or `config` itself when it is the context already built (the inputs
    were checked when it was)."""
    given = config if isinstance(config, StudyContext) else None
    config = config.config if isinstance(config, StudyContext) else config
    ATTEMPTS.check(attempts)
    if scheduler is not None and scheduler != "local":
        check_scheduler_address(scheduler)
        check_scheduler_reachable(scheduler)
    engine_function(config.engine)  # fail fast, once, if the engine is missing
    # every input file, and the policies, once, before any worker
    context = given if given is not None else study_context(config, progress)
    check_record_ids(config, plan_episodes(config))
    return context


def check_before_writing(config: StudyConfig | StudyContext, study_dir: Path, scheduler: str | None,
                         attempts: int, progress: bool) -> StudyContext:
    """Every refusal of a study run, before its directory, its lock or its mark is written: the
    inputs and the scheduler (`validate_study`), a directory that holds another study or files that
    are not a study's, and one where a folder the study writes in is not a folder; the directory
    first, as the inputs may take minutes (a missing policy is synthesized). Returns the study's
    context (`validate_study`'s)."""
    check_study_output(study_dir)
    check_own_folder(Path(study_dir))
    check_study_folders(Path(study_dir))
    context = validate_study(config, scheduler, attempts, progress)
    recorded_config_hash(Path(study_dir), context.config.content_hash)
    return context


SCHEDULER_CONNECT_SECONDS = 5.0


def check_scheduler_reachable(scheduler: str) -> None:
    """A tcp:// (or bare HOST:PORT) Dask scheduler accepts connections, checked before anything is
    written (dask's own client would only fail after its timeout, with the study folder made). Other
    protocols (tls, ws, inproc, ucx) are left to dask."""
    import socket

    protocol, _, address = scheduler.rpartition("://")
    if protocol not in ("", "tcp"):
        return
    host, _, port = address.rpartition(":")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=SCHEDULER_CONNECT_SECONDS).close()
    except (OSError, ValueError) as exc:
        raise InputError("--scheduler", scheduler[:80], f"cannot reach the Dask scheduler ({exc})",
                         "start one with `dask scheduler` and pass its address, or use --scheduler local"
                         ) from None


def check_scheduler_address(scheduler: str) -> None:
    """A Dask scheduler address must look like tcp://HOST:PORT (or HOST:PORT) before we dial it."""
    import re

    match = re.fullmatch(r"(?:(tcp|tls|ws|wss|inproc|ucx)://)?([A-Za-z0-9_.\-\[\]:]+):(\d{1,5})", scheduler)
    if match is None or not 0 < int(match.group(3)) < 65536:
        raise InputError("--scheduler", scheduler[:80], "not a Dask scheduler address",
                         "pass tcp://HOST:PORT (from `dask scheduler`), or 'local'")


def run_study(
    config: StudyConfig | StudyContext,
    study_dir: Path,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    on_outcome: Callable[[EpisodeOutcome], None] | None = None,
    dask_processes: bool = True,
    attempts: int = defaults.ATTEMPTS,
) -> StudyRun:
    """Run (or resume) every episode of `config` in `study_dir`; return what happened.

    config: the study's config, or its context when the caller built it already (`validate_study`).
    workers: local processes (1: in this process); scheduler: a Dask scheduler address, or
    "local" for a local Dask cluster of `workers` workers (threads in this process when
    dask_processes is False, which tests use). on_outcome: called after every episode.
    attempts: runs of a failing episode at most (the first and its retries)."""
    study_dir = Path(study_dir).resolve()
    context = check_before_writing(config, study_dir, scheduler, attempts, progress)
    with open_study_dir(study_dir, context.config):
        return _run_locked(context, study_dir, workers, scheduler, progress, on_outcome, dask_processes,
                           attempts)


def _run_locked(
    context: StudyContext,
    study_dir: Path,
    workers: int,
    scheduler: str | None,
    progress: bool,
    on_outcome: Callable[[EpisodeOutcome], None] | None,
    dask_processes: bool,
    attempts: int,
) -> StudyRun:
    started = time.perf_counter()
    config = context.config
    tasks = plan_episodes(config)
    check_record_ids(config, tasks)
    done, damaged = finished_episodes(study_dir, tasks)
    todo = [t for t in tasks if t.episode_id not in done]
    function = functools.partial(run_unit, str(study_dir))
    ran = retried = 0
    failed: dict[str, tuple[EpisodeTask, EpisodeOutcome]] = {}
    errors: dict[str, list[str]] = {}
    by_id = {t.episode_id: t for t in todo}
    bar = _progress_bar(len(tasks), len(done), progress)

    def consume(outcomes: Iterable[EpisodeOutcome]) -> None:
        nonlocal ran
        for outcome in outcomes:
            ran += 1
            if ran % (SYNC_EVERY * (BATCH_EPISODES if config.engine == "model" else 1)) == 0:
                sync_parts(study_dir)
            if outcome.ok:
                failed.pop(outcome.episode_id, None)
                bar.update(1)
            else:
                failed[outcome.episode_id] = (by_id[outcome.episode_id], outcome)
                errors.setdefault(outcome.episode_id, []).append(outcome.error)
            if on_outcome is not None:
                on_outcome(outcome)

    with sigterm_raises():
        consume(_outcomes(function, context, plan_units(config, todo, workers), workers, scheduler,
                          dask_processes))
        for _ in range(attempts - 1):  # after everything else: a transient failure gets another chance
            retry = [task for task, outcome in failed.values() if outcome.retry]
            if not retry:
                break
            retried += len(retry)
            consume(_outcomes(function, context, [(task,) for task in retry], workers, scheduler,
                              dask_processes))
    bar.close()
    sync_parts(study_dir)
    for task, outcome in failed.values():
        history = errors[task.episode_id]
        write_failure(study_dir, task, outcome.error, outcome.traceback, len(history), history)
    return StudyRun(
        study_dir=study_dir,
        planned=len(tasks),
        skipped=len(done),
        damaged=damaged,
        ran=ran,
        failed=sorted(failed),
        retried=retried,
        seconds=time.perf_counter() - started,
        backend=backend_name(workers, scheduler),
        context=context,
    )


def _progress_bar(total: int, initial: int, enabled: bool) -> tqdm:
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        unit="episode",
        disable=bar_disable(enabled),
        dynamic_ncols=True,
        leave=False,
    )


def run_and_consolidate(
    config: StudyConfig | StudyContext,
    study_dir: Path,
    workers: int,
    scheduler: str | None,
    progress: bool = True,
    echo: Callable[[str], object] = print,
    dask_processes: bool = True,
    attempts: int = defaults.ATTEMPTS,
) -> tuple[StudyRun, dict]:
    """Run (or resume) the study, then write the consolidated dataset and manifest (with the
    exact values and synthesized bounds of its policies). `echo` gets one summary line. The study
    directory stays locked until the manifest is written. config: the study's config, or its
    context when the caller built it already (`validate_study`); the run's `context` is the one
    the episodes and the consolidation used."""
    study = config.config if isinstance(config, StudyContext) else config
    if not ENGINES[study.engine].synthetic:
        raise InputError(study.source_path, "study.engine",
                         "a live study is driven by people, not simulated",
                         "serve it with `trustroute live CONFIG`, or simulate it with --engine sumo")
    study_dir = Path(study_dir).resolve()
    context = check_before_writing(config, study_dir, scheduler, attempts, progress)
    with open_study_dir(study_dir, context.config):
        for _ in range(CONSOLIDATION_ROUNDS):
            run = _run_locked(context, study_dir, workers, scheduler, progress, None, dask_processes,
                              attempts)
            try:
                return run, _consolidate_run(context, run, echo, progress)
            except DamagedParts as exc:  # damaged between the run and consolidation: moved aside
                echo(f"notice: consolidation found {exc}; running them again")
    raise InputError(str(study_dir), "parts", "parts fail verification as soon as they are written",
                     "check the disk holding the study directory")


def _consolidate_run(context: StudyContext, run: StudyRun, echo: Callable[[str], object],
                     progress: bool = False) -> dict:
    echo(
        f"{counted(run.planned, 'episode')} planned: {run.skipped} already done, {run.ran - run.retried} run"
        f"{f', {run.retried} retried' if run.retried else ''}, {len(run.failed)} failed"
        f"{f', {len(run.damaged)} damaged parts re-run' if run.damaged else ''} "
        f"({run.backend}, {run.seconds:.1f} s)"
    )
    config = context.config
    expected = expected_values(context)
    for line in fallback_only_warnings(expected):
        print(line, file=sys.stderr)
    return consolidate(
        run.study_dir,
        context,
        plan_episodes(config),
        config.content_hash,
        expected,
        {
            "backend": run.backend,
            "seconds": run.seconds,
            "skipped": run.skipped,
            "damaged": run.damaged,
            "retried": run.retried,
        },
        progress=progress,
    )
