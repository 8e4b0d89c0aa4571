"""The study condition "robust": the type-aware policy of a driver population beside "free", its
episodes run on the type-aware filter (the roads table logs the trust marginal), and the expected
values evaluate it on its own filter with the nominal driver. (Horizon 3: phi1 needs 6 junctions,
so synthesis is answered by graph distance and the test stays fast; the policy's own synthesis is
tested in tests/policies/synthesis/test_population_synthesis.py.)"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from trustroute.core.errors import InputError
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.runner import run_and_consolidate
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH
from trustroute.policies.belief.driver_types import TypeLiftedModel


def config_file(tmp_path, conditions: str, extra: str = "") -> object:
    path = tmp_path / "study.toml"
    path.write_text(f"""[study]
participants = 3
seed = 5
engine = "model"
specs = ["phi1"]
conditions = {conditions}
horizon = 3
policy_cache = "{tmp_path / 'cache'}"
{extra}
""")
    return path


@pytest.mark.slow
def test_robust_condition_runs_on_the_type_aware_filter(tmp_path):
    from trustroute.harness.study.context import study_context
    from trustroute.harness.study.expected import expected_values

    path = config_file(tmp_path, '["robust", "free"]', f'robust_population = "{EXAMPLE_POPULATION_PATH}"')
    config = load_study_config(path)
    context = study_context(config)
    setup = context.setup("phi1", "robust")
    assert isinstance(setup.driver_model, TypeLiftedModel) and setup.driver_model.n_types == 3
    assert context.setup("phi1", "free") is context.setups["phi1"]
    cached = list((tmp_path / "cache").glob("robust-phi1-*.json"))
    assert len(cached) == 1 and json.loads(cached[0].read_text())["objective"] == "robust"
    run_and_consolidate(context, tmp_path / "out", 1, None, progress=False, echo=lambda *_: None)
    episodes = pd.read_parquet(tmp_path / "out" / "episodes.parquet")
    roads = pd.read_parquet(tmp_path / "out" / "roads.parquet")
    assert sorted(episodes["condition"].unique()) == ["free", "robust"]
    robust_roads = roads[roads["episode_id"].str.endswith("-robust")]
    beliefs = np.stack(robust_roads["belief_after"].to_numpy())
    assert beliefs.shape[1] == 7 and np.allclose(beliefs.sum(axis=1), 1.0)
    entry = expected_values(context)["phi1"]["robust"]
    assert 0.0 <= entry["exact_lower"] <= entry["exact_upper"] <= 1.0


def test_robust_condition_needs_its_population(tmp_path):
    with pytest.raises(InputError, match="robust_population"):
        load_study_config(config_file(tmp_path, '["robust"]'))
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    with pytest.raises(InputError, match="bad.json"):
        load_study_config(config_file(tmp_path, '["robust"]', f'robust_population = "{bad}"'))


def test_the_robust_population_enters_the_study_hash(tmp_path):
    plain = load_study_config(config_file(tmp_path, '["free"]'))
    with_key = load_study_config(config_file(tmp_path, '["free"]',
                                             f'robust_population = "{EXAMPLE_POPULATION_PATH}"'))
    assert with_key.content_hash != plain.content_hash


@pytest.mark.slow
def test_robust_condition_with_a_trust_state_spec_runs_on_the_joint_policy(tmp_path):
    from pathlib import Path

    from trustroute.harness.study.context import study_context
    from trustroute.policies.routing.trust_state_table import JointTablePolicy

    spec = Path("specs/phi1_trust.toml").resolve()
    path = config_file(tmp_path, '["robust", "free"]', f'robust_population = "{EXAMPLE_POPULATION_PATH}"')
    path.write_text(path.read_text().replace('specs = ["phi1"]', f'specs = ["{spec}"]'))
    config = load_study_config(path)
    context = study_context(config)
    assert isinstance(context.policies[("phi1_trust", "robust")], JointTablePolicy)
    run_and_consolidate(context, tmp_path / "out", 1, None, progress=False, echo=lambda *_: None)
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    robust, free = manifest["expected"]["phi1_trust"]["robust"], manifest["expected"]["phi1_trust"]["free"]
    # the joint unfolding evaluates the AV's own model only: the nominal driver's value is not given
    assert robust["exact_lower"] is None and "hidden trust" in robust["not_evaluated"]
    assert robust["synthesized_lower"] <= robust["synthesized_upper"]
    # nothing pruned: the bracket is one computed value rounded outward (policies/synthesis/rounding.py)
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.synthesis.rounding import evaluation_rounding, relative_margin

    nominal = build_pomdp(context.town, context.nominal)
    margin = relative_margin(evaluation_rounding(nominal, context.specs["phi1_trust"], True),
                             config.junction_cap, "bayes")
    # (L down by the margin, U up by twice it, each one float further out)
    width = 3.0 * margin * free["exact_upper"] + 2.0 * np.spacing(free["exact_upper"])
    assert 0.0 < free["exact_upper"] - free["exact_lower"] <= width
    episodes = pd.read_parquet(tmp_path / "out" / "episodes.parquet")
    assert set(episodes["condition"]) == {"robust", "free"}
