"""The study context is built from the config: settings that change the drivers change the context."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.context import study_context

STUDY = """[study]
participants = 3
seed = 5
engine = "model"
specs = ["phi1"]
conditions = ["free"]
"""


def _config(tmp_path: Path, name: str, population: str):
    path = tmp_path / name
    path.write_text(STUDY + population)
    return load_study_config(path)


def test_configs_differing_only_in_population_get_their_own_context(tmp_path):
    """An in-process sweep over [population] settings must run each setting's drivers."""
    # The same file name in two folders: the configs differ in [population] and nothing else.
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    narrow = _config(tmp_path / "a", "study.toml", "[population]\nconcentration = 1000.0\n")
    wide = _config(tmp_path / "b", "study.toml", "[population]\nconcentration = 2.0\ntakeover_spread = 1.0\n")
    wide = type(wide)(**{**wide.__dict__, "source_path": narrow.source_path})
    assert narrow.population != wide.population and narrow.content_hash != wide.content_hash
    first, second = study_context(narrow), study_context(wide)
    assert first.config.population == narrow.population
    assert second.config.population == wide.population
    different = [not np.allclose(a.trust_transition, b.trust_transition)
                 for a, b in zip(first.participants, second.participants, strict=True)]
    assert all(different)
    assert narrow != wide and hash(narrow) != hash(wide)


def test_each_build_is_the_callers_own(tmp_path):
    """study_context caches nothing: equal configs build equal contexts, each a new one that its
    builder holds and passes down."""
    a = _config(tmp_path, "study.toml", "[population]\nconcentration = 30.0\n")
    b = _config(tmp_path, "study.toml", "[population]\nconcentration = 30.0\n")
    assert a == b and hash(a) == hash(b)
    first, second = study_context(a), study_context(b)
    assert first is not second and first.config == second.config
    assert all(np.array_equal(x.trust_transition, y.trust_transition)
               for x, y in zip(first.participants, second.participants, strict=True))


def test_nominal_and_population_configs_do_not_share_a_context(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    nominal = _config(tmp_path / "a", "study.toml", "")
    varied = _config(tmp_path / "b", "study.toml", "[population]\nconcentration = 5.0\n")
    varied = type(varied)(**{**varied.__dict__, "source_path": nominal.source_path})
    assert study_context(nominal).participants is None
    assert study_context(varied).participants is not None


def test_the_reference_filter_is_one_rule_for_the_plan_and_the_analysis(tmp_path):
    """The "reference" source's filter (harness/study/context.py, `reference_model`): the robust
    population's type-aware model, else the [drivers] population's, else the driver model; the
    robust condition's own model object when the caller holds it; the context's is the same rule,
    also for a config that names a robust population without running that condition."""
    from trustroute.app.inputs import driver_of
    from trustroute.harness.study.context import reference_model
    from trustroute.participants.driver_population import (
        EXAMPLE_POPULATION_PATH,
        POPULATIONS,
        load_driver_population,
    )
    from trustroute.policies.belief.driver_types import TypeLiftedModel

    nominal, held = driver_of(None), driver_of(None)
    three, real = str(EXAMPLE_POPULATION_PATH), str(POPULATIONS.resolve("driver_population_real"))
    assert reference_model({}, nominal) is nominal
    assert reference_model({"robust_population": str(tmp_path / "gone.json")}, nominal) is nominal
    both = reference_model({"robust_population": three, "driver_population": real}, nominal)
    assert isinstance(both, TypeLiftedModel) and both.n_types == 3
    drivers = reference_model({"robust_population": None, "driver_population": real}, nominal)
    # a one-type population's type-aware model is its type's model
    only = load_driver_population(real).types[0].model
    assert drivers is not nominal and drivers.provenance == only.provenance != nominal.provenance
    assert reference_model({"robust_population": three}, nominal, robust=held) is held
    assert reference_model({"driver_population": three}, nominal, robust=held) is not held

    config = _config(tmp_path, "study.toml", "")
    context = study_context(type(config)(**{**config.__dict__, "robust_population": three}))
    assert not context.condition_setups   # "free" only: no robust AV to take the model from
    filtered = context.reference_filter
    assert isinstance(filtered, TypeLiftedModel) and filtered.n_types == 3
    assert context.reference_filter is filtered
