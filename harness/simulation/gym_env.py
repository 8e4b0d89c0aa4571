"""The gymnasium environment `trustroute/TrustRouting-v0`: the agent routes the AV junction by junction.

Importing this module registers the id (as sumo-rl does for its environments); without the import,
`gymnasium.make("trustroute.harness.simulation.gym_env:trustroute/TrustRouting-v0")` imports it itself.
docs/gym_env.md documents the spaces, the reward and the ends.

The environment does not re-implement an episode. It steps the project's own episode objects
(harness/simulation/stepping.py), `model_engine.ModelEpisode` (engine "model": the trust POMDP, no
SUMO) or `episode.SumoEpisode` (engine "sumo": libsumo), the very objects studies run: `reset`
advances a new episode to its first decision point, `step(action)` answers it with the junction
(`choose`) and advances to the next decision point or the end. No thread: the episode runs only
inside `reset` and `step`. So the tracker's rules (belief filter, DFA, accept, reject, junction
cap) and the synthetic driver's draws are exactly those of studies; the study's 20-junction
fallback is off (the agent decides every junction). Every draw (the driver's initial trust,
takeovers, trust moves, reports, and the SUMO seed) comes from the `np_random` Generator that
`reset(seed=...)` seeds.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium
import numpy as np
from gymnasium import spaces

from trustroute.app.drivers import draw_type, gym_episode_id, synthetic_driver
from trustroute.app.engines import SIMULATED, check_sumo_only, engine_named
from trustroute.app.problem import load_problem
from trustroute.app.synthesis import EvaluationOutcome, EvaluationSettings, evaluate_problem
from trustroute.core import defaults
from trustroute.core.errors import InputError, keyword_names
from trustroute.core.fields import PROBABILITY, check_value
from trustroute.core.settings import with_options
from trustroute.core.wording import shown_value
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.stepping import DecisionPoint, SteppableEpisode
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DEFAULT_REPORT_ACCURACY, DriverModel
from trustroute.participants.driver_population import DriverPopulation
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BELIEF_RULE_NAMES
from trustroute.policies.routing.episode_rules import JUNCTION_CAPS
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

if TYPE_CHECKING:
    from collections.abc import Callable, Hashable, Mapping

    from trustroute.harness.simulation.episode_record import EpisodeRecord
    from trustroute.policies.model.trust_pomdp import BeliefRule

ENV_ID = "trustroute/TrustRouting-v0"
ENGINES: tuple[str, ...] = SIMULATED   # the engines a synthetic driver drives (trustroute/app/engines.py)
DEFAULT_JUNCTION_CAP = EpisodeSetup.junction_cap
# Summary fields that are not a function of the seed and the actions (the episode counter in the id,
# the wall time): kept out of info["summary"], so equal seeds and actions give equal info, and
# given in `last_run` instead.
RUN_FACTS = ("episode_id", "wall_seconds")


@dataclass(frozen=True)
class EnvSettings:
    """How the environment's episodes run. engine: "model" (fast, no SUMO) or "sumo" (libsumo).
    junction_cap: the episode ends after this many junctions (the task's horizon). belief_rule: the
    AV's filter ("bayes" or "paper"). report_accuracy: the synthetic driver's trust-report accuracy
    (reports are logged only). net_path: the SUMO net (None: the town's; the SUMO engine's only).
    Every field is checked here, by the rules a study config's keys of the same names follow; a bad
    one is an InputError naming it."""

    engine: str = defaults.GYM_ENGINE
    junction_cap: int = DEFAULT_JUNCTION_CAP
    belief_rule: BeliefRule = defaults.BELIEF_RULE
    report_accuracy: float = DEFAULT_REPORT_ACCURACY
    net_path: str | Path | None = None

    def __post_init__(self) -> None:
        engine = engine_named(self.engine, "EnvSettings", "engine", simulated=True)
        check_value(self.junction_cap, JUNCTION_CAPS, "EnvSettings", "junction_cap",
                    lambda seen: f"expected an integer from {JUNCTION_CAPS.minimum} to "
                                 f"{JUNCTION_CAPS.maximum}, got {shown_value(seen.value)}",
                    f"pass a whole number of junctions, e.g. junction_cap={DEFAULT_JUNCTION_CAP}")
        check_value(self.belief_rule, BELIEF_RULE_NAMES, "EnvSettings", "belief_rule",
                    fix="pass 'bayes' or 'paper'")
        check_value(self.report_accuracy, PROBABILITY, "EnvSettings", "report_accuracy",
                    fix=f"pass a number in [0, 1], e.g. report_accuracy={DEFAULT_REPORT_ACCURACY}")
        if self.net_path is not None and not isinstance(self.net_path, str | Path):
            raise InputError("EnvSettings", "net_path",
                             f"expected a file path, got {shown_value(self.net_path)}",
                             "pass the path of a SUMO .net.xml, or None for the town's net")
        check_sumo_only(engine, self.net_path, "a SUMO net", "EnvSettings", "net_path")


class AgentPolicy(RoutingPolicy):
    """The episode's policy when the agent chooses every junction (through `step`): it never ends
    an episode itself and no fallback drives, so the episode rules (policies/routing/episode_rules.py)
    only read the DFA and the junction cap before offering the agent a decision point."""

    name = "agent"

    def next_junction(self, context: DecisionContext) -> str:
        raise RuntimeError("the agent chooses the junction through TrustRoutingEnv.step")


class ActingPolicy(RoutingPolicy):
    """An agent of the environment (observation -> action) as a routing policy: at each decision
    it is given the observation the environment gives there and its action is read as `step`
    reads it. Made by `TrustRoutingEnv.agent_policy`."""

    def __init__(self, env: TrustRoutingEnv, act: Callable[[dict], Any], name: str) -> None:
        self._env, self._act, self.name = env, act, name

    def next_junction(self, context: DecisionContext) -> str:
        return self._env.junction_for(context.road, self._act(self._env.observation_at(context)))

    def route_memory(self, route: tuple[str, ...]) -> Hashable:
        # the observation holds the current road, the junctions driven, the DFA state and the
        # belief, and nothing else of the route: histories equal in those are acted on alike
        return ()


class TrustRoutingEnv(gymnasium.Env):
    """Route the AV through a town so that an scLDTL spec is satisfied; reward 1 on acceptance.

    spec: a Spec, a spec file or a packaged spec name ("phi1"). town, driver: objects, files,
    packaged names ("pentagon", "driver_model_performance"), or None for the packaged defaults
    (a packaged spec's own town: "city5" drives "city"; trustroute/app/inputs.py) (the driver
    model is both the AV's filter model and the synthetic driver's). settings: an EnvSettings
    (engine, junction_cap, belief_rule, report_accuracy, net_path); any of its fields may instead
    be given by keyword (`engine="sumo"`, as gymnasium.make passes them), over `settings`.
    population: a driver population (object or file; instead of driver): the AV's filter is its
    type-aware model and the spec is lifted onto it; each episode's driver is of a type drawn from
    the weights (`driver_type`).

    Observation (Dict): "road" (index into town.states), "dfa_state" (the spec's DFA state after
    the current position), "belief" (the AV's belief over trust levels), "junctions" (driven so
    far). Action: Discrete(max out-degree); action a at a road with k legal next junctions
    (town.actions(road), sorted) drives to junction a mod k, so every action is legal;
    info["action_mask"] marks the k legal ones (for `action_space.sample(mask=...)`). Anything not
    in the action space is a ValueError, and the episode goes on.

    info is a function of the seed and the actions: the last step's info["summary"] leaves out the
    episode id and wall time (RUN_FACTS), which `last_run` holds with the episode counter.

    `agent_policy(act)` turns an agent (observation -> action) into a routing policy that
    `trustroute.run_episode` drives and records; `evaluate_agent(act)` is its exact expected return
    (docs/gym_env.md, "An agent as a policy").
    """

    metadata = {"render_modes": []}

    def __init__(self, spec: Spec | str | Path = "phi1", town: Town | str | Path | None = None,
                 driver: DriverModel | str | Path | None = None, *, settings: EnvSettings | None = None,
                 render_mode: str | None = None, population: DriverPopulation | str | Path | None = None,
                 **options: Any) -> None:
        settings = with_options(settings, EnvSettings(), options, "TrustRoutingEnv")
        if render_mode is not None:
            raise ValueError("TrustRouting has no render modes "
                             "(record a SUMO episode with trustroute run --rrd)")
        # The compiled problem (trustroute/app): with a driver population the AV filters with its
        # type-aware model and reads the lifted spec (docs/driver_types.md); each episode's driver
        # is of a type drawn from its weights.
        try:
            self.problem = load_problem(spec, town, driver, population)
        except InputError as error:   # said as the API says it: `town`, not the CLI's --town
            raise keyword_names(error) from None
        self.town = self.problem.town
        self.population = self.problem.population
        self.driver_model = self.problem.driver
        self.scldtl_spec = self.problem.spec
        self.driver_type: str | None = None     # the type of the current episode's driver
        self.settings = settings
        self._belief_rule: BeliefRule = settings.belief_rule
        self._belief = np.asarray(self.driver_model.initial_belief, dtype=np.float64)  # at the last decision
        self.engine = settings.engine
        self.report_accuracy = float(settings.report_accuracy)
        self.net_path = Path(settings.net_path) if settings.net_path is not None else None
        self.setup = EpisodeSetup.of(self.problem, junction_cap=int(settings.junction_cap),
                                     fallback_after=None, belief_rule=settings.belief_rule)
        self._legal = {road: self.town.actions(road) for road in self.town.states}
        self._width = max(len(actions) for actions in self._legal.values())
        self.action_space = spaces.Discrete(self._width)
        self.observation_space = spaces.Dict({
            "road": spaces.Discrete(len(self.town.states)),
            "dfa_state": spaces.Discrete(int(compile_spec(self.scldtl_spec, self.town).dfa.n_states)),
            "belief": spaces.Box(0.0, 1.0, shape=(self.driver_model.n_trust,), dtype=np.float64),
            "junctions": spaces.Discrete(self.setup.junction_cap + 1),
        })
        self.render_mode = None
        self.last_record: EpisodeRecord | None = None      # of the last finished episode
        self.last_run: dict = {}  # the last episode's facts that differ between identical runs
        self.episodes = 0         # episodes started by reset()
        self._episode: SteppableEpisode | None = None   # the running episode, None once over
        self._road = ""
        self._check_start()

    # -- the episode -----------------------------------------------------------------------------
    def _driver(self, rng: np.random.Generator) -> SyntheticDriver:
        """An episode's synthetic driver, of a type drawn from the population when there is one."""
        model = self.driver_model
        if self.population is not None:
            self.driver_type, model = draw_type(self.population, rng)
        return synthetic_driver(model, rng, report_accuracy=self.report_accuracy)

    def _check_start(self) -> None:
        """InputError when the spec is decided on its start road, so that no episode has a junction
        to choose. The start position is read on the initial belief alone (the hidden trust of a
        trust-state spec leaves its joint belief undecided there), so one model-engine episode
        with any driver tells."""
        from trustroute.harness.simulation.model_engine import ModelEpisode

        probe = ModelEpisode(self.setup, AgentPolicy(), self._driver(np.random.default_rng(0)), "start", 0)
        point = probe.advance()
        self.driver_type = None
        if not isinstance(point, DecisionPoint):
            spec = self.scldtl_spec
            raise InputError(spec.source_path or spec.name, "start",
                             f"the spec is decided on its start road {spec.start} "
                             f"({point.record.summary['end_reason']}): an episode has no junction to "
                             "choose", "start the spec on a road where its formula is not yet decided")
        probe.close()

    def _new_episode(self, driver: SyntheticDriver, episode_id: str, sumo_seed: int) -> SteppableEpisode:
        if not engine_named(self.engine).drives_sumo:
            from trustroute.harness.simulation.model_engine import ModelEpisode

            return ModelEpisode(self.setup, AgentPolicy(), driver, episode_id, sumo_seed)
        from trustroute.harness.simulation.episode import EpisodeOptions, SumoEpisode

        return SumoEpisode(self.setup, AgentPolicy(), driver, episode_id, sumo_seed,
                           EpisodeOptions(net_path=self.net_path))

    def _close_episode(self) -> None:
        """End a running episode (its SUMO session closes)."""
        episode, self._episode = self._episode, None
        if episode is not None:
            episode.close()

    def _advance(self):
        """The running episode advanced; an error ends it (and is raised)."""
        try:
            return self._episode.advance()
        except BaseException:
            self._episode = None   # it closed itself
            raise

    # -- observations ---------------------------------------------------------------------------
    def _observed(self, road: str, dfa_state: int, belief: np.ndarray, junctions: int) -> dict:
        return {
            "road": int(self.town.state_index(road)),
            "dfa_state": int(dfa_state),
            "belief": np.array(belief, dtype=np.float64),
            "junctions": int(junctions),
        }

    def _info(self) -> dict:
        legal = self._legal[self._road]
        mask = np.zeros(self._width, dtype=np.int8)
        mask[: len(legal)] = 1
        return {"action_mask": mask, "road_name": self._road, "legal_junctions": tuple(legal)}

    def _decision(self, context: DecisionContext) -> dict:
        """The observation at the decision point `context`, whose road and belief `step` and the
        final observation then read."""
        self._road, self._belief = context.road, np.asarray(context.belief, dtype=np.float64)
        return self.observation_at(context)

    def observation_at(self, context: DecisionContext) -> dict:
        """The observation the environment gives at the decision point `context`."""
        return self._observed(context.road, context.dfa_state, context.belief, context.junctions_driven)

    def junction_for(self, road: str, action: object) -> str:
        """The junction `step(action)` drives to from `road` (ValueError for an action not in the
        action space)."""
        legal = self._legal[road]
        return legal[self._checked(action) % len(legal)]

    def _final_belief(self, last: Mapping[str, Any]) -> np.ndarray:
        """The AV's belief after the last road. The roads table logs a type-aware belief's trust
        marginal only: with a population, the last decision's belief is filtered once more with
        the last road's observation, as the tracker does."""
        if self.population is None:
            return np.asarray(last["belief_after"], dtype=np.float64)
        from trustroute.harness.simulation.episode_tracker import PERFORMANCE_INDEX
        from trustroute.policies.model.trust_pomdp import build_pomdp

        pomdp = build_pomdp(self.town, self.driver_model)
        incident = self.driver_model.incident_index(str(last["incident"]))
        posterior, _ = pomdp.filter(self._belief, incident, int(bool(last["takeover"])),
                                    PERFORMANCE_INDEX[str(last["performance"])], rule=self._belief_rule)
        return posterior[0]

    def _final(self, record: EpisodeRecord) -> tuple[dict, float, bool, bool, dict]:
        self._episode = None
        self.last_record = record
        last = record.last_road()
        summary = {k: v for k, v in record.summary.items() if k not in RUN_FACTS}
        if self.engine == "model":  # no simulated clock: sim_seconds is NaN, which equals nothing
            summary.pop("sim_seconds", None)
        self.last_run = {"episode": self.episodes,
                         **{k: record.summary[k] for k in RUN_FACTS if k in record.summary}}
        self._road = str(last["directed_road"])
        observation = self._observed(self._road, int(last["dfa_state"]), self._final_belief(last),
                                     int(summary["junctions"]))
        reason = summary["end_reason"]
        info = {**self._info(), "end_reason": reason, "summary": summary}
        # The episode's own reading of the spec: the DFA's acceptance, and for a spec that tests
        # the hidden trust the true DFA state's (an episode the AV cannot settle ends at the cap).
        # The cap is the task's horizon, not a limit outside it: the reward certified values speak
        # of is for acceptance within it, a spec on the hidden trust is read there, and the
        # observation counts the junctions. So every end is `terminated` (gymnasium's rule for a
        # limit the agent sees); a bootstrapping learner would otherwise add a value after the
        # cap that the task does not have.
        return observation, float(bool(summary["satisfied"])), True, False, info

    # -- the gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        self._close_episode()
        rng = self.np_random
        sumo_seed = int(rng.integers(0, 2**31 - 1))
        driver = self._driver(rng)
        self.episodes += 1
        episode_id = gym_episode_id(self.scldtl_spec.name, self.episodes)
        self._episode = self._new_episode(driver, episode_id, sumo_seed)
        point = self._advance()
        # every episode reaches a decision point: a spec decided on its start road is refused when
        # the environment is made (_check_start), and no junction cap is below 1
        if not isinstance(point, DecisionPoint):
            raise RuntimeError(f"episode {episode_id} ended before its first junction, which the "
                               "environment's start check rules out: please report it")
        return self._decision(point.context), self._info()

    def step(self, action: int) -> tuple[dict, float, bool, bool, dict]:
        if self._episode is None:
            raise RuntimeError("the episode is over (or never started): call reset()")
        junction = self.junction_for(self._road, action)
        try:
            self._episode.choose(junction)
        except BaseException:
            self._close_episode()
            raise
        point = self._advance()
        if isinstance(point, DecisionPoint):
            return self._decision(point.context), 0.0, False, False, self._info()
        return self._final(point.record)

    def _checked(self, action: object) -> int:
        """`action` as an int, or ValueError (the episode goes on) when it is not in the action
        space: an int or numpy integer scalar in 0..n-1, never a bool, float, string or array."""
        if isinstance(action, (bool, np.bool_)) or not self.action_space.contains(action):
            raise ValueError(f"action {action!r} is not in the action space {self.action_space}: pass "
                             f"an integer from 0 to {self._width - 1} (info[\"action_mask\"] marks the "
                             "legal ones)")
        return int(action)  # type: ignore[call-overload]

    # -- an agent as a routing policy -----------------------------------------------------------
    def agent_policy(self, act: Callable[[dict], Any], name: str = "agent") -> RoutingPolicy:
        """The agent `act` (an observation of this environment -> an action) as a routing policy:
        `trustroute.run_episode(spec, policy, ...)` drives it (with the study's fallback and a
        Rerun recording, `rrd=`) and `trustroute.evaluate` values it. `act` must be a
        deterministic function of the observation."""
        return ActingPolicy(self, act, name)

    def evaluate_agent(self, act: Callable[[dict], Any], *, max_nodes: int | None = None,
                       time_limit: float | None = None) -> EvaluationOutcome:
        """The exact probability that the agent `act` (deterministic, observation -> action) is
        rewarded in an episode of this environment, certified in [lower, upper]: its expected return,
        by `trustroute.evaluate`'s unfolding with this environment's junction cap, belief rule and
        no fallback (over the population's mixture of types when it has one, each type's value in
        `type_values`). max_nodes and time_limit bound the unfolding as `trustroute.evaluate`'s do
        (fewer nodes or less time: a wider bracket), under the same rules (an InputError naming the
        keyword)."""
        try:
            settings = EvaluationSettings(fallback_after=None, max_junctions=self.setup.junction_cap,
                                          belief_rule=self._belief_rule, max_nodes=max_nodes,
                                          time_limit=time_limit)
            return evaluate_problem(self.problem, lambda: self.agent_policy(act), settings)
        except InputError as error:   # said as the API says it: `max_nodes`, not --max-nodes
            raise keyword_names(error) from None

    def render(self) -> None:
        """Nothing: there are no render modes, and gymnasium's rule for `render_mode=None` is that no
        render is computed (the base class would raise NotImplementedError instead)."""
        return None

    def close(self) -> None:
        self._close_episode()
        super().close()


def register() -> None:
    """Register ENV_ID with gymnasium (idempotent)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point=f"{__name__}:TrustRoutingEnv")


register()
