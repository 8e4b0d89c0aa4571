"""The engine registry: `model`, `sumo` and `live`, each declaring what it can do.

Callers ask an engine's capabilities instead of comparing its name: whether SUMO drives it (SUMO
options, kinematics logs, the net), whether a synthetic driver drives it (a study can simulate
it; `live` is driven by people in their browsers, `trustroute live`), and whether an episode can be
re-run with a Rerun recording or shown in sumo-gui. `run` is the episode function:
run(setup, policy, driver, episode_id, seed[, EpisodeOptions for SUMO]) -> EpisodeRecord.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from trustroute.core.errors import InputError
from trustroute.core.wording import shown_value
from trustroute.harness.simulation.episode import EpisodeRecord, run_episode
from trustroute.harness.simulation.model_engine import run_model_episode


@dataclass(frozen=True)
class Engine:
    name: str
    run: Callable[..., EpisodeRecord]
    drives_sumo: bool       # SUMO runs the episode: SUMO options, a net, kinematics logged
    synthetic: bool         # a synthetic driver drives it, so a study simulates it (else people do)
    description: str

    @property
    def records(self) -> bool:
        """An episode can be re-simulated with a Rerun recording or shown in sumo-gui."""
        return self.drives_sumo and self.synthetic


ENGINES: dict[str, Engine] = {engine.name: engine for engine in (
    Engine("sumo", run_episode, drives_sumo=True, synthetic=True,
           description="libsumo: incidents, takeovers and performance measured in the simulation"),
    Engine("model", run_model_episode, drives_sumo=False, synthetic=True,
           description="the trust POMDP alone, no SUMO"),
    Engine("live", run_episode, drives_sumo=True, synthetic=False,
           description="SUMO with people driving in their browsers (`trustroute live`)"),
)}
SIMULATED: tuple[str, ...] = tuple(name for name, engine in ENGINES.items() if engine.synthetic)


def engine_named(name: str, where: str = "engine", place: str = "", simulated: bool = False) -> Engine:
    """The engine called `name` (`simulated`: one a synthetic driver drives); InputError otherwise,
    at `where` (a flag, a keyword, a file) and `place` in it (a field), as any other check there."""
    names = SIMULATED if simulated else tuple(ENGINES)
    if name not in names:
        raise InputError(where, place, f"unknown engine {shown_value(name)}",
                         f"use one of {', '.join(names)}")
    return ENGINES[name]


def check_sumo_only(engine: Engine, given: object, what: str, where: str, place: str = "") -> None:
    """A setting only SUMO reads (`given`, not None; `what` names it: "a SUMO net") refused on an
    engine that does not drive SUMO, an InputError at `where` and `place`, rather than dropped
    unread."""
    if given is None or engine.drives_sumo:
        return
    raise InputError(where, place, f"{what} needs the SUMO engine, not {engine.name!r}",
                     f"run on the SUMO engine (engine 'sumo') or drop {place or where}")
