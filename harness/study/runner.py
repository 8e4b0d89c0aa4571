"""Running a study: plan, skip what is done, run the rest on a backend, consolidate.

One worker function, `run_task(config, study_dir, task)`, runs an episode and writes its part; it
never raises (an error comes back as a failed `EpisodeOutcome`). Three backends hand it tasks:
in-process (`workers=1`), a local process pool (`workers=N`), and Dask distributed
(`scheduler="ADDRESS"`, or `scheduler="local"` for a local Dask cluster). Each worker process
builds the study's context (town, specs, policies, participants' driver models) once, from the
config alone, so nothing large travels with the tasks and the result cannot depend on the
backend. A failed episode is retried once; if it fails again its error is recorded in
failures/ and the study goes on. A rerun resumes: valid parts are skipped, damaged parts re-run.
"""

from __future__ import annotations

import functools
import json
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from trustroute.analysis.dataset import STUDY_FILE
from trustroute.harness.episode_tracker import EpisodeSetup
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.parts import finished_episodes, write_failure, write_part
from trustroute.harness.study.plan import EpisodeTask, participant_models, plan_episodes
from trustroute.networks.errors import InputError
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.protocol import RoutingPolicy


@dataclass(frozen=True)
class EpisodeOutcome:
    episode_id: str
    ok: bool
    error: str = ""
    traceback: str = ""
    wall_seconds: float = 0.0


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


# -- the study's context, built once per worker process -----------------------------------------


@dataclass(frozen=True, eq=False)
class StudyContext:
    """What every episode of a study shares; built from the config alone."""

    config: StudyConfig
    town: Town
    nominal: DriverModel  # the AV's model (its belief filter) and the default driver
    specs: dict[str, Spec]
    setups: dict[str, EpisodeSetup]
    policies: dict[tuple[str, str], RoutingPolicy]  # (spec name, condition label) -> policy
    participants: list[DriverModel] | None  # per-participant driver models; None: all nominal

    def driver_model(self, participant: int) -> DriverModel:
        return self.nominal if self.participants is None else self.participants[participant]


def aware_policy_path(town: Town, driver: DriverModel, spec: Spec, config: StudyConfig) -> Path:
    """Where the "aware" policy of this study is cached (the resolver's entry for its horizon and filter)."""
    from trustroute.policies.routing.resolve import aware_cache_path

    return aware_cache_path(town, driver, spec, config.policy_cache, aware_horizon(config),
                            config.belief_rule)


def aware_horizon(config: StudyConfig) -> int:
    """The synthesis horizon of "aware": the config's, else the resolver's default (20 junctions)."""
    from trustroute.policies.routing.resolve import AWARE_HORIZON

    return AWARE_HORIZON if config.horizon is None else config.horizon


def resolve_condition_policy(
    condition: str, town: Town, driver: DriverModel, spec: Spec, config: StudyConfig, progress: bool = False
) -> RoutingPolicy:
    """A condition ("free", "aware": synthesized and cached if missing, or a policy file) as a policy."""
    from trustroute.policies.routing.resolve import resolve_policy

    return resolve_policy(condition, town, driver, spec, config.policy_cache, aware_horizon(config),
                          config.belief_rule, progress)


@functools.lru_cache(maxsize=4)
def study_context(config: StudyConfig, progress: bool = False) -> StudyContext:
    """The study's shared context, built once per process (cached by the config). progress: bars while
    policies are synthesized (the main process; workers find them in the policy cache)."""
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec

    town = load_town(config.town)
    nominal = load_driver_model(config.driver_model)
    specs = {Path(path).stem: load_spec(path, town) for path in config.specs}
    setups = {
        name: EpisodeSetup(
            town=town,
            driver_model=nominal,
            spec=spec,
            junction_cap=config.junction_cap,
            fallback_after=config.fallback_after,
            report_every=config.report_every,
            belief_rule=config.belief_rule,
        )
        for name, spec in specs.items()
    }
    policies = {
        (name, label): resolve_condition_policy(condition, town, nominal, spec, config, progress)
        for name, spec in specs.items()
        for condition, label in zip(config.conditions, config.condition_names, strict=True)
    }
    return StudyContext(
        config=config,
        town=town,
        nominal=nominal,
        specs=specs,
        setups=setups,
        policies=policies,
        participants=participant_models(config, nominal),
    )


def engine_function(engine: str) -> Callable:
    """The episode function of an engine (run_episode for SUMO, run_model_episode for the model)."""
    if engine == "model":
        from trustroute.harness.model_engine import run_model_episode

        return run_model_episode
    from trustroute.harness.episode import run_episode

    return run_episode


RECORDINGS_DIR = "recordings"


def recording_path(study_dir: Path, episode_id: str) -> Path:
    """Where a study keeps the Rerun recording of an episode named in its config's `record`."""
    return Path(study_dir) / RECORDINGS_DIR / f"{episode_id}.rrd"


def run_planned_episode(config: StudyConfig, task: EpisodeTask, rrd_path: Path | None = None,
                        sumo_config=None):
    """Run the planned episode `task` exactly as the study runs it: the participant's driver model
    (population draw), the driver's Generator from the task's seed sequence (so the same initial trust
    and every later draw), SUMO's seed, the cell's setup and policy. Returns the EpisodeRecord.

    rrd_path and sumo_config (e.g. sumo-gui) apply to the SUMO engine only."""
    from trustroute.participants.synthetic_driver import SyntheticDriver

    context = study_context(config)
    driver = SyntheticDriver(
        context.driver_model(task.participant), task.driver_rng(), report_accuracy=config.report_accuracy
    )
    options = {}
    if config.engine == "sumo":
        from trustroute.harness.sumo_start import SumoConfig

        sumo_config = replace(sumo_config if sumo_config is not None else SumoConfig(),
                              background_vehicles=config.background_vehicles)
        options = {"rrd_path": rrd_path, "config": sumo_config}
    return engine_function(config.engine)(
        context.setups[task.spec],
        context.policies[(task.spec, task.condition)],
        driver,
        task.episode_id,
        task.seed,
        **options,
    )


def run_task(config: StudyConfig, study_dir: str, task: EpisodeTask) -> EpisodeOutcome:
    """Run one episode and write its part. Never raises: errors come back in the outcome."""
    started = time.perf_counter()
    try:
        rrd = recording_path(Path(study_dir), task.episode_id) if task.episode_id in config.record else None
        record = run_planned_episode(config, task, rrd_path=rrd)
        write_part(
            Path(study_dir),
            task,
            record.summary,
            record.roads,
            record.kinematics,
            getattr(record, "incidents", None),
        )
    except Exception as exc:  # one bad episode must never stop the study
        return EpisodeOutcome(
            task.episode_id,
            False,
            f"{type(exc).__name__}: {exc}",
            traceback.format_exc(),
            time.perf_counter() - started,
        )
    return EpisodeOutcome(task.episode_id, True, wall_seconds=time.perf_counter() - started)


def check_record_ids(config: StudyConfig, tasks: list[EpisodeTask]) -> None:
    """The config's `record` names planned episodes of a SUMO study, or InputError."""
    if not config.record:
        return
    if config.engine != "sumo":
        raise InputError(config.source_path, "study.record", "recordings need the SUMO engine",
                         'set engine = "sumo" or remove record')
    planned = {t.episode_id for t in tasks}
    unknown = [e for e in config.record if e not in planned]
    if unknown:
        raise InputError(config.source_path, "study.record",
                         f"{unknown[0]!r} is not an episode of this study",
                         f"use ids like {tasks[0].episode_id!r} (p<participant>-<spec>-<condition>)")


# -- backends: each yields outcomes as they complete -------------------------------------------


def _serial(function: Callable, tasks: list) -> Iterator:
    for task in tasks:
        yield function(task)


def _process_pool(function: Callable, tasks: list, workers: int) -> Iterator:
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(function, task): task for task in tasks}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:  # a worker process died (killed, out of memory)
                task = futures[future]
                yield EpisodeOutcome(task.episode_id, False, f"worker died: {type(exc).__name__}: {exc}")


def _dask(function: Callable, tasks: list, scheduler: str, workers: int, processes: bool) -> Iterator:
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
        except OSError as exc:
            raise InputError(
                "--scheduler",
                scheduler,
                f"cannot reach the Dask scheduler ({exc})",
                "start one with `dask scheduler` and pass its address, or use --scheduler local",
            ) from None
    try:
        futures = {client.submit(function, task, pure=False): task for task in tasks}
        for future in as_completed(futures):
            try:
                yield future.result()
            except Exception as exc:
                task = futures[future]
                yield EpisodeOutcome(task.episode_id, False, f"dask: {type(exc).__name__}: {exc}")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _outcomes(
    function: Callable, tasks: list, workers: int, scheduler: str | None, dask_processes: bool = True
) -> Iterator:
    if not tasks:
        return iter(())
    if scheduler is not None:
        return _dask(function, tasks, scheduler, workers, dask_processes)
    if workers <= 1:
        return _serial(function, tasks)
    return _process_pool(function, tasks, min(workers, len(tasks)))


def backend_name(workers: int, scheduler: str | None) -> str:
    if scheduler is not None:
        return f"dask ({scheduler})"
    return "in-process" if workers <= 1 else f"process pool ({workers} workers)"


# -- the study ---------------------------------------------------------------------------------


def check_study_dir(study_dir: Path, config: StudyConfig, config_hash: str) -> None:
    """Create the study directory, or check that it holds this study (resume) and not another."""
    study_dir.mkdir(parents=True, exist_ok=True)
    marker = study_dir / STUDY_FILE
    if marker.exists():
        try:
            recorded = json.loads(marker.read_text()).get("config_hash")
        except (OSError, json.JSONDecodeError):
            recorded = None
        if recorded is not None and recorded != config_hash:
            raise InputError(
                str(study_dir),
                STUDY_FILE,
                "the directory holds a study with a different config (hash mismatch)",
                "pass another --out, or delete the directory to start over",
            )
        if recorded == config_hash:
            return
    config_dict = asdict(config)
    marker.write_text(json.dumps({"config_hash": config_hash, "config": config_dict}, indent=1, default=str))


def run_study(
    config: StudyConfig,
    study_dir: Path,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    on_outcome: Callable[[EpisodeOutcome], None] | None = None,
    dask_processes: bool = True,
) -> StudyRun:
    """Run (or resume) every episode of `config` in `study_dir`; return what happened.

    workers: local processes (1: in this process); scheduler: a Dask scheduler address, or
    "local" for a local Dask cluster of `workers` workers (threads in this process when
    dask_processes is False, which tests use). on_outcome: called after every episode."""
    started = time.perf_counter()
    study_dir = Path(study_dir).resolve()
    config_hash = config.content_hash
    check_study_dir(study_dir, config, config_hash)
    engine_function(config.engine)  # fail fast, once, if the engine is missing
    context = study_context(config, progress)  # resolves (and synthesizes) policies once, before any worker
    del context
    tasks = plan_episodes(config)
    check_record_ids(config, tasks)
    done, damaged = finished_episodes(study_dir, tasks)
    todo = [t for t in tasks if t.episode_id not in done]
    function = functools.partial(run_task, config, str(study_dir))
    ran = 0
    failed: dict[str, tuple[EpisodeTask, EpisodeOutcome]] = {}
    by_id = {t.episode_id: t for t in todo}
    bar = _progress_bar(len(tasks), len(done), progress)

    def consume(outcomes: Iterable[EpisodeOutcome]) -> None:
        nonlocal ran
        for outcome in outcomes:
            ran += 1
            if outcome.ok:
                failed.pop(outcome.episode_id, None)
                bar.update(1)
            else:
                failed[outcome.episode_id] = (by_id[outcome.episode_id], outcome)
            if on_outcome is not None:
                on_outcome(outcome)

    consume(_outcomes(function, todo, workers, scheduler, dask_processes))
    retry = [task for task, _ in failed.values()]
    if retry:  # once, after everything else: a transient failure gets a second chance
        consume(_outcomes(function, retry, workers, scheduler, dask_processes))
    bar.close()
    for task, outcome in failed.values():
        write_failure(study_dir, task, outcome.error, outcome.traceback, attempts=2)
    return StudyRun(
        study_dir=study_dir,
        planned=len(tasks),
        skipped=len(done),
        damaged=damaged,
        ran=ran,
        failed=sorted(failed),
        retried=len(retry),
        seconds=time.perf_counter() - started,
        backend=backend_name(workers, scheduler),
    )


def _progress_bar(total: int, initial: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(
        total=total,
        initial=initial,
        unit="episode",
        disable=None if enabled else True,
        dynamic_ncols=True,
        leave=False,
    )


def run_and_consolidate(
    config: StudyConfig,
    study_dir: Path,
    workers: int,
    scheduler: str | None,
    progress: bool = True,
    echo: Callable[[str], object] = print,
    dask_processes: bool = True,
) -> tuple[StudyRun, dict]:
    """Run (or resume) the study, then write the consolidated dataset and manifest (with the
    exact values and synthesized bounds of its policies). `echo` gets one summary line."""
    from trustroute.harness.study.expected import expected_values
    from trustroute.harness.study.manifest import consolidate

    run = run_study(
        config,
        study_dir,
        workers=workers,
        scheduler=scheduler,
        progress=progress,
        dask_processes=dask_processes,
    )
    echo(
        f"{run.planned} episodes planned: {run.skipped} already done, {run.ran - run.retried} run"
        f"{f', {run.retried} retried' if run.retried else ''}, {len(run.failed)} failed"
        f"{f', {len(run.damaged)} damaged parts re-run' if run.damaged else ''} "
        f"({run.backend}, {run.seconds:.1f} s)"
    )
    expected = expected_values(config)
    manifest = consolidate(
        run.study_dir,
        config,
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
    return run, manifest
