"""Policy names to policies: "free", "aware" (synthesized once, then cached) or a policy file.

"aware" is `synthesize(pomdp, spec, horizon=AWARE_HORIZON, tau=AWARE_TAU)` with the Bayes filter:
H = 20 junctions because the study measures "policy, then the shortest completion after 20
junctions" (policies.fallback), so maximising P(accepted within 20) is the objective the study
actually scores. It is cached in `cache_dir` under a key made of the content hashes of town,
driver model and spec, these settings and the synthesis code's version
(policies/synthesis/version.py); a cache entry is a policy file like any other.
"""

from __future__ import annotations

import contextlib
import hashlib
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeGuard, TypeVar

from trustroute.core import defaults
from trustroute.core.cache import POLICIES, entry_lock_path
from trustroute.core.cache import cache_dir as cache_dir_of
from trustroute.core.errors import InputError
from trustroute.core.output_files import file_lock
from trustroute.core.package import check_outside_package
from trustroute.core.wording import outward
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.belief.problem import TRUST_STATE, case_of
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, build_pomdp
from trustroute.policies.routing.files import array_path, load_policy, load_population_policy, save_policy
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.synthesis.population import OBJECTIVES, document_entries, policy_name, run_count
from trustroute.policies.synthesis.result import RoundProgress
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesis.version import JOINT_SYNTHESIS_VERSION, SYNTHESIS_VERSION
from trustroute.policies.synthesize_spec import synthesize_for_population
from trustroute.policies.synthesize_spec import synthesize_spec as synthesize

if TYPE_CHECKING:
    from trustroute.participants.driver_population import DriverPopulation
    from trustroute.policies.synthesis.population import Objective

Loaded = TypeVar("Loaded")

AWARE_HORIZON = defaults.AWARE_HORIZON   # synthesize for the junctions before the fallback takes over
AWARE_TAU = 1e-3
AWARE_TIME_LIMIT = 120.0


@dataclass(frozen=True)
class PolicySettings:
    """How a named policy is found or made: the policy cache (None: the cache root's), the horizon
    and AV filter "aware" and population policies are synthesized for, and whether a synthesis
    shows its progress."""

    cache_dir: str | Path | None = None
    horizon: int | None = AWARE_HORIZON
    belief_rule: BeliefRule = defaults.BELIEF_RULE
    progress: bool = False

    def __post_init__(self) -> None:
        if self.cache_dir is not None:   # every door's: a package is published read-only
            check_outside_package(Path(self.cache_dir), "--cache-dir", "policy cache")


DEFAULT_POLICY = PolicySettings()


def _code_version(case: str) -> str:
    """The synthesis code's part of a cache key: SYNTHESIS_VERSION, and for problems whose DFA state
    is hidden (TRUST_STATE, synthesized by policies/trust_state_synthesis/synthesis.py) also
    JOINT_SYNTHESIS_VERSION."""
    joint = f"+joint={JOINT_SYNTHESIS_VERSION}" if case == TRUST_STATE else ""
    return f"synthesis={SYNTHESIS_VERSION}{joint}"


def aware_cache_path(town: Town, driver: DriverModel, spec: Spec, cache_dir: str | Path | None,
                     horizon: int | None = AWARE_HORIZON, belief_rule: BeliefRule = "bayes") -> Path:
    """Cache entry of the "aware" policy for these inputs (horizon None: unbounded; cache_dir None:
    the policies folder of the cache root, trustroute.core.cache). The key covers the inputs'
    contents, the settings and the synthesis code's version (`_code_version`)."""
    key = hashlib.sha256("|".join((town.content_hash, driver.content_hash, spec.content_hash,
                                   f"H={horizon}", f"tau={AWARE_TAU}", belief_rule,
                                   _code_version(case_of(driver, spec)))).encode())
    folder = Path(cache_dir) if cache_dir else cache_dir_of(POLICIES)
    # The spec name is only a readable label here (the key identifies the entry): keep it to
    # file-name characters so no name can point outside the cache.
    label = re.sub(r"[^A-Za-z0-9_.+-]", "_", spec.name)[:48].lstrip(".") or "spec"
    return folder / f"aware-{label}-{key.hexdigest()[:16]}.json"


def _cached_policy(path: Path, load: Callable[[Path], Loaded],
                   notice: Callable[[str], object]) -> Loaded | None:
    """The cache entry at `path`, read by `load`, if it verifies; a damaged entry is discarded
    (with a notice)."""
    if not path.exists() and not array_path(path).exists():
        return None
    try:
        return load(path)
    except InputError as exc:
        notice(f"notice: discarding the damaged policy cache entry {path.name} ({exc.problem}); "
               "synthesizing it again")
        for stale in (path, array_path(path)):
            with contextlib.suppress(FileNotFoundError):
                stale.unlink()
        return None


def _stderr(message: str) -> None:
    print(message, file=sys.stderr)


def aware_policy(town: Town, driver: DriverModel, spec: Spec, cache_dir: str | Path | None,
                 horizon: int | None = AWARE_HORIZON, belief_rule: BeliefRule = "bayes",
                 notice: Callable[[str], object] = _stderr, progress: bool = False) -> RoutingPolicy:
    """The cached "aware" policy, synthesized when missing or damaged (progress: a bar while
    synthesizing). Entries are written atomically (policies.routing.files), filled under a lock
    (two processes never synthesize one entry at once, and the second reads what the first wrote)
    and verified on every read."""
    path = aware_cache_path(town, driver, spec, cache_dir, horizon, belief_rule)

    def load(entry: Path) -> RoutingPolicy:
        return load_policy(entry, town, driver, spec)

    if path.is_file():
        policy = _cached_policy(path, load, notice)
        if policy is not None:
            return policy
    with file_lock(entry_lock_path(path), "policy cache entry", wait=True,
                   fix="pass a writable --cache-dir"):
        policy = _cached_policy(path, load, notice)  # filled while we waited?
        if policy is not None:
            return policy
        with synthesis_progress(f"synthesizing aware for {spec.name}", progress) as on_iteration:
            result = synthesize(build_pomdp(town, driver), spec,
                                SynthesisSettings(tau=AWARE_TAU, time_limit=AWARE_TIME_LIMIT, horizon=horizon,
                                                  belief_rule=belief_rule),
                                on_iteration=on_iteration)
        save_policy(result, path, town, driver, spec)
    return result.policy


def resolve_policy(name_or_path: str, town: Town, driver: DriverModel, spec: Spec,
                   cache_dir: str | Path | None = None, horizon: int | None = AWARE_HORIZON,
                   belief_rule: BeliefRule = "bayes", progress: bool = False) -> RoutingPolicy:
    """"free", "aware" or the path of a policy file, as a RoutingPolicy for this town/model/spec.

    horizon: the junction horizon "aware" is synthesized for (default 20; None: unbounded).
    belief_rule: the AV filter "aware" is synthesized for. progress: a progress bar while synthesizing.
    """
    if name_or_path == "free":
        return trust_free_policy(town, spec)
    if name_or_path == "aware":
        return aware_policy(town, driver, spec, cache_dir, horizon, belief_rule, progress=progress)
    if not Path(name_or_path).exists():  # anything that exists goes to the guarded reader
        raise InputError(name_or_path, "", "not a policy file and not 'free' or 'aware'",
                         "pass 'free', 'aware' or the path of a policy file written by trustroute synth")
    return load_policy(name_or_path, town, driver, spec)


PROGRESS_AFTER = 2.0    # seconds: a synthesis shorter than this shows no progress
PROGRESS_EVERY = 5.0    # seconds between progress lines when stderr is not a terminal


@contextlib.contextmanager
def synthesis_progress(description: str, enabled: bool) -> Iterator[RoundProgress]:
    """Progress of a synthesis on stderr once it has run PROGRESS_AFTER seconds, nothing when not
    `enabled`: on a terminal a tqdm bar of its rounds with the current bounds; elsewhere (a pipe, a
    log file) a line at most every PROGRESS_EVERY seconds with the rounds, the bounds and the time.
    Yields the `on_iteration(lower, upper)` callback."""
    if not enabled:
        yield lambda lower, upper: None
        return
    if sys.stderr.isatty():
        from tqdm import tqdm

        with tqdm(desc=description, unit="round", delay=PROGRESS_AFTER, leave=False, dynamic_ncols=True,
                  file=sys.stderr) as bar:
            def on_round(lower: float | None, upper: float) -> None:
                bar.update(1)
                bar.set_postfix_str(_bounds_text(lower, upper), refresh=False)

            yield on_round
        return
    yield _progress_lines(description)


def _bounds_text(lower: float | None, upper: float) -> str:
    """A progress report's current bounds, four decimals rounded outward (`outward`); before the
    synthesis has an L to show (no policy valued yet), it says so rather than print a 0."""
    low, high = outward(0.0 if lower is None else lower, upper, 4)
    return f"{'L not yet (no policy valued)' if lower is None else f'L={low}'} U={high}"


def _say(description: str, text: str, seconds: float | None = None) -> None:
    """One progress line on stderr, `description: text (N s)` (the time so far, when given)."""
    print(f"{description}: {text}" + ("" if seconds is None else f" ({seconds:.0f} s)"), file=sys.stderr,
          flush=True)


def _progress_lines(description: str) -> RoundProgress:
    """The on_iteration callback of `synthesis_progress` away from a terminal."""
    started = time.perf_counter()
    rounds = 0
    due = PROGRESS_AFTER

    def on_round(lower: float | None, upper: float) -> None:
        nonlocal rounds, due
        rounds += 1
        elapsed = time.perf_counter() - started
        if elapsed >= due:
            _say(description, f"{rounds} rounds, {_bounds_text(lower, upper)}", elapsed)
            due = elapsed + PROGRESS_EVERY

    return on_round


@contextlib.contextmanager
def step_progress(description: str, enabled: bool) -> Iterator[Callable[[str], None]]:
    """Progress of a run of long steps that report nothing while they run (a peer's solver, an
    export): once the run has taken PROGRESS_AFTER seconds, a line on stderr every PROGRESS_EVERY seconds
    naming the step under way and the time so far, from a timer thread; nothing when not `enabled`.
    Yields `step(name)`, called as each step starts."""
    if not enabled:
        yield lambda name: None
        return
    started = time.perf_counter()
    current = [""]
    stop = threading.Event()

    def tick() -> None:
        wait = PROGRESS_AFTER
        while not stop.wait(wait):
            if current[0]:
                _say(description, current[0], time.perf_counter() - started)
            wait = PROGRESS_EVERY

    timer = threading.Thread(target=tick, daemon=True)
    timer.start()
    try:
        yield lambda name: current.__setitem__(0, name)
    finally:
        stop.set()
        timer.join()


def phase_lines(description: str, enabled: bool) -> Callable[[str], None]:
    """The on_phase callback of a population synthesis: its lines (one per finished synthesis run,
    with its bounds) on stderr once PROGRESS_AFTER seconds have passed; nothing when not `enabled`."""
    started = time.perf_counter()

    def on_phase(line: str) -> None:
        if enabled and time.perf_counter() - started >= PROGRESS_AFTER:
            _say(description, line)

    return on_phase


POPULATION_TIME_LIMIT = 60.0     # per synthesis run of a population policy (the call gets one per run)
POPULATION_GRID_POINTS = 6       # candidate type priors of the robust objective


def population_cache_path(town: Town, population: DriverPopulation, spec: Spec, objective: str,
                          cache_dir: str | Path | None, horizon: int | None = AWARE_HORIZON,
                          belief_rule: BeliefRule = "bayes") -> Path:
    """Cache entry of the population policy ("robust" or "bayes" objective) for these inputs: the
    key covers the population's content hash instead of one driver model's, and the code version
    that of the problem's case (a trust-state spec: the trust-state search's version too)."""
    key = hashlib.sha256("|".join((town.content_hash, population.content_hash, spec.content_hash,
                                   objective, f"H={horizon}", f"tau={AWARE_TAU}", belief_rule,
                                   f"grid={POPULATION_GRID_POINTS}",
                                   _code_version(case_of(population.types[0].model, spec)))).encode())
    folder = Path(cache_dir) if cache_dir else cache_dir_of(POLICIES)
    label = re.sub(r"[^A-Za-z0-9_.+-]", "_", spec.name)[:48].lstrip(".") or "spec"
    return folder / f"{objective}-{label}-{key.hexdigest()[:16]}.json"


def is_objective(name: str) -> TypeGuard[Objective]:
    """`name` is an objective of population synthesis ("bayes" or "robust")."""
    return name in OBJECTIVES


def population_policy(town: Town, population: DriverPopulation, spec: Spec, objective: str = "robust",
                      settings: PolicySettings = DEFAULT_POLICY, population_source: str = "",
                      notice: Callable[[str], object] = _stderr) -> tuple[RoutingPolicy, DriverModel, Spec]:
    """The cached policy of `objective` for driver population `population` (a DriverPopulation),
    synthesized when missing or damaged (policies/synthesis/population.py): (policy, the lifted
    driver model its AV filters with, the lifted spec). One type: the "aware" policy of that
    type's model. `settings`: the cache, the horizon and AV filter it is made for, progress."""
    cache_dir, horizon, belief_rule, progress = (settings.cache_dir, settings.horizon, settings.belief_rule,
                                                 settings.progress)
    lifted_spec = lift_spec(spec, population, population_source)
    if population.n_types == 1:
        model = lift_population(population)
        return (aware_policy(town, model, lifted_spec, cache_dir, horizon, belief_rule, notice, progress),
                model, lifted_spec)
    path = population_cache_path(town, population, spec, objective, cache_dir, horizon, belief_rule)

    def cached() -> tuple[RoutingPolicy, DriverModel, Spec] | None:
        return _cached_policy(
            path, lambda p: load_population_policy(p, town, population, spec, population_source), notice)

    if path.is_file():
        found = cached()
        if found is not None:
            return found
    with file_lock(entry_lock_path(path), "policy cache entry", wait=True,
                   fix="pass a writable --cache-dir"):
        found = cached()
        if found is not None:
            return found
        if not is_objective(objective):
            raise ValueError(f"unknown objective {objective!r}; use 'bayes' or 'robust'")
        description = f"synthesizing {objective} for {spec.name}"
        with synthesis_progress(description, progress) as on_iteration:
            runs = run_count(population, objective, POPULATION_GRID_POINTS)
            made = synthesize_for_population(town, population, spec, objective,
                                             SynthesisSettings(tau=AWARE_TAU,
                                                               time_limit=POPULATION_TIME_LIMIT * runs,
                                                               horizon=horizon, belief_rule=belief_rule,
                                                               grid_points=POPULATION_GRID_POINTS),
                                             population_source=population_source,
                                             on_iteration=on_iteration,
                                             on_phase=phase_lines(description, progress))
        save_policy(made.result, path, town, made.pomdp.driver, made.spec,
                    population=document_entries(made), name=policy_name(made))
        # read back: a fresh entry and a cached one give the same policy object
        return load_population_policy(path, town, population, spec, population_source)
