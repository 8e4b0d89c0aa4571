"""The belief sources a study's conditions are compared on, and which one leads by default.

Every source labels each logged position with a belief over trust (docs/study.md):

- "filter": each AV's own online filter, the logged `belief_after` (what that vehicle believed;
  under the `robust` condition the type-aware filter, under `aware` and `free` the nominal one);
- "reported": beliefs induced from the driver's reported trust (analysis/satisfaction.py);
- "reference": one exact Bayes filter for every condition, run on each episode's logged
  observations (incident, takeover, performance): the study's driver model, or the type-aware
  filter of the population when the study has one (its trust marginal);
- "true" (simulated studies only): the exact Bayes filter of each driver's own true model (the
  participant's type, or the individual sampled for it), what an AV knowing the driver would believe.

The primary source (the one the tables lead with) is the study config's `belief_source`, declared
before the study runs (pre-registered); without one it is the neutral default,
`default_belief_source`: "true" for simulated studies, whose drivers' own models the analysis knows,
"reported" for live and imported ones. Both are the same for every condition: neither is any
condition's own filter. "filter" scores each condition on its own AV's belief and "reference" on
the type-aware filter, which is the `robust` AV's own: they stay available (`--belief-source`, or
declared) but are never the default, and the report's sensitivity table shows every comparison on
every source. `trustroute analyze` and `trustroute.analyze()` both read the default here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.core.errors import InputError
from trustroute.core.package import is_package
from trustroute.harness.study.config import BELIEF_SOURCES as BELIEF_SOURCES  # the names, re-exported
from trustroute.harness.study.config import StudyConfig
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.belief.observed import observed_beliefs

# why a package has no "true" source when its drivers differ (a [population], a [drivers] population)
PACKAGE_TRUE_SOURCE = ("each participant's own number to rebuild their driver's model, which the package's "
                       "pseudonymous codes hide")
# why a simulated study has none when this installation cannot rebuild its drivers
UNBUILT_TRUE_SOURCE = ("the drivers' own models, which this installation cannot rebuild from the study's "
                       "config")
# engines whose drivers are simulated from models the study config names ("true" exists)
SIMULATED_ENGINES: tuple[str, ...] = ("model", "sumo")
# conditions whose AV filters with another model than the study's driver model
OWN_FILTER_CONDITIONS: tuple[str, ...] = ("robust",)
PERFORMANCE_INDEX = {"succ": 0, "fail": 1}


def filters_differ(manifest: dict) -> bool:
    """True when the study's conditions filter with different models (a `robust` condition)."""
    conditions = (manifest.get("config") or {}).get("conditions") or []
    return any(str(c) in OWN_FILTER_CONDITIONS for c in conditions)


def neutral_belief_source(manifest: dict) -> str:
    """The source neutral to every condition: each driver's own exact filter ("true") in a
    simulated study, the driver's reports ("reported") in a live or imported one."""
    return neutral_source_of(manifest.get("engine"))


def neutral_source_of(engine: object) -> str:
    """The neutral source of a study on `engine`: "true" where its drivers are simulated."""
    return "true" if engine in SIMULATED_ENGINES else "reported"


def config_belief_source(config: StudyConfig) -> str:
    """The primary source of the study `config` describes, before it runs (what `trustroute plan`
    judges its simulated episodes on): the declared one, else the neutral one of its own engine,
    the rule `default_belief_source` applies to the study's manifest."""
    return config.belief_source or neutral_source_of(config.engine)


def declared_belief_source(manifest: dict) -> str | None:
    """The primary source the study config declared (`[study] belief_source`), if any."""
    declared = (manifest.get("config") or {}).get("belief_source")
    return str(declared) if declared else None


def default_belief_source(manifest: dict) -> str:
    """The primary source of a study's analysis: the declared one, else the neutral one (the one
    definition every entry point reads: the CLI, the Python API, the report)."""
    return declared_belief_source(manifest) or neutral_belief_source(manifest)


def beside_source(source: str) -> str:
    """The source whose rate the cells show beside the leading one's."""
    return "reported" if source == "filter" else "filter"


def source_label(source: str) -> str:
    """How a table names its belief source."""
    return {
        "filter": "each AV's own filter",
        "reported": "induced from reported trust",
        "reference": "one reference filter for every condition",
        "true": "exact filter of each driver's true model",
    }[source]


def judged_on(source: str) -> str:
    """How a plan (its terminal table, its pre-registration) names the source its satisfaction
    power is computed on: the study's primary one, as its analysis will judge the episodes."""
    return (f"satisfaction judged on beliefs from: {source} ({source_label(source)}), "
            "the study's primary source")


def refiltered(roads: pd.DataFrame, model: DriverModel, town: Town) -> pd.DataFrame:
    """`roads` (sorted by episode and index) with `belief_after` replaced by the exact Bayes filter
    of `model` run on the logged observations; its trust marginal for a type-aware model. An
    observation the model gives probability 0 keeps the belief (never a zero row)."""
    from trustroute.policies.model.trust_pomdp import build_pomdp

    roads = roads.sort_values(["episode_id", "index"], kind="stable").reset_index(drop=True)
    if not len(roads):
        return roads
    pomdp = build_pomdp(town, model)
    _, starts, lengths = np.unique(roads["episode_id"].to_numpy(), return_index=True, return_counts=True)
    n, horizon = lengths.size, int(lengths.max())
    row = np.repeat(np.arange(n), lengths)
    col = np.arange(len(roads)) - np.repeat(starts, lengths)
    incident = np.zeros((n, horizon), dtype=np.int64)
    takeover = np.zeros((n, horizon), dtype=np.int64)
    performance = np.zeros((n, horizon), dtype=np.int64)
    incident[row, col] = [model.incident_index(str(i)) for i in roads["incident"].fillna("none")]
    takeover[row, col] = roads["takeover"].fillna(False).astype(bool).to_numpy().astype(np.int64)
    performance[row, col] = roads["performance"].fillna("succ").map(PERFORMANCE_INDEX).to_numpy()
    marginal = observed_beliefs(pomdp, incident, takeover, performance)[row, col]
    return roads.assign(belief_after=list(marginal))


class SourceUnavailable(InputError):
    """A belief source the study cannot give; `needs`: what it would need (the analysis' note on
    the missing source says it, and so does the error for asking for it)."""

    def __init__(self, study_dir: Path, source: str, needs: str) -> None:
        self.needs = needs
        super().__init__(str(study_dir), "", f"belief source {source!r} needs {needs}",
                         "use filter, reported or reference")


def true_roads(study_dir: Path, manifest: dict, roads: pd.DataFrame, episodes: pd.DataFrame,
               nominal: DriverModel, town: Town) -> pd.DataFrame:
    """`roads` on the "true" source: each episode's roads filtered with its driver's true model.
    `SourceUnavailable`, saying why, when the drivers cannot be rebuilt from `manifest`'s config
    (`UNBUILT_TRUE_SOURCE`), or (in a package `trustroute export` wrote) each participant's model
    needs their number, which the package's codes hide (`PACKAGE_TRUE_SOURCE`)."""
    from trustroute.harness.study.plan import participant_models
    from trustroute.harness.study.replay import study_config_from_manifest

    try:
        config, _ = study_config_from_manifest(study_dir, manifest)
        models = participant_models(config, nominal)
    except InputError:
        raise SourceUnavailable(study_dir, "true", UNBUILT_TRUE_SOURCE) from None
    if models is None:
        return refiltered(roads, nominal, town)
    if is_package(study_dir):
        raise SourceUnavailable(study_dir, "true", PACKAGE_TRUE_SOURCE)
    # one filter run per distinct model (the types' models are shared by their participants)
    distinct = {id(m): i for i, m in enumerate(models)}
    model_of = {p: distinct[id(m)] for p, m in enumerate(models)}
    participant_of = dict(zip(episodes["episode_id"], episodes["participant"], strict=True))
    owner = roads["episode_id"].map(lambda e: model_of[int(participant_of[e])])
    frames = [refiltered(group, models[int(index)], town) for index, group in roads.groupby(owner, sort=True)]
    return pd.concat(frames, ignore_index=True) if frames else roads
