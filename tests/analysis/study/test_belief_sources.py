"""One belief source for every condition compared: a study with the `robust` condition (whose AV
filters with the type-aware model) beside `aware` and `free` (the nominal filter) is judged by
default on the reference filter, the same for every condition; the report says which source leads.
(Horizon 3 keeps synthesis fast, as in tests/harness/test_study_robust.py.)"""

from __future__ import annotations

import html

import numpy as np
import pytest
from click.testing import CliRunner

from trustroute.analysis.belief_sources import (
    default_belief_source,
    reference_model,
    refiltered,
    true_roads,
)
from trustroute.analysis.study.analysis import study_analysis
from trustroute.analysis.study_directory import load_study, study_inputs
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.runner import run_and_consolidate
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.policies.belief.driver_types import TypeLiftedModel


@pytest.fixture(scope="module")
def robust_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("robust_study")
    path = root / "study.toml"
    path.write_text(f"""[study]
participants = 6
seed = 5
engine = "model"
specs = ["phi1"]
conditions = ["aware", "robust", "free"]
horizon = 3
policy_cache = "{root / 'cache'}"
robust_population = "{EXAMPLE_POPULATION_PATH}"

[drivers]
population = "{EXAMPLE_POPULATION_PATH}"
""")
    run_and_consolidate(load_study_config(path), root / "out", 1, None, progress=False, echo=lambda *_: None)
    return root / "out"


@pytest.mark.slow
def test_the_default_source_is_common_to_every_condition(robust_study):
    manifest, episodes, roads = load_study(robust_study)
    assert default_belief_source(manifest) == "reference"
    analysis = study_analysis(robust_study, resamples=50)
    assert analysis.belief_source == "reference"
    town, driver, _ = study_inputs(manifest)
    model = reference_model(manifest, driver)
    assert isinstance(model, TypeLiftedModel) and model.n_types == 3
    reference = refiltered(roads, model, town).set_index(["episode_id", "index"])["belief_after"]
    logged = roads.set_index(["episode_id", "index"])["belief_after"].loc[reference.index]
    condition = reference.index.get_level_values(0).map(
        dict(zip(episodes["episode_id"], episodes["condition"], strict=True)))
    reference_b, logged_b = np.stack(reference.to_numpy()), np.stack(logged.to_numpy())
    # the robust AV's own filter is the reference filter: identical beliefs on its roads ...
    robust = np.asarray(condition == "robust")
    assert np.allclose(reference_b[robust], logged_b[robust], atol=1e-12)
    # ... while the aware AV's own (nominal) filter differs from it, so "filter" is not common
    aware = np.asarray(condition == "aware")
    assert not np.allclose(reference_b[aware], logged_b[aware], atol=1e-6)
    # every condition's satisfaction on the default source is that of the reference beliefs
    assert {"satisfied_filter", "satisfied_reported", "satisfied_reference", "satisfied_true"} <= set(
        analysis.episodes.columns)
    assert analysis.cells["satisfied"].tolist() == [
        int(analysis.episodes[analysis.episodes["condition"] == c]["satisfied_reference"].sum())
        for c in analysis.cells["condition"]]


@pytest.mark.slow
def test_true_source_filters_with_each_drivers_type(robust_study):
    manifest, episodes, roads = load_study(robust_study)
    town, driver, _ = study_inputs(manifest)
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    true = true_roads(robust_study, roads, episodes, driver, town)
    for type_name in episodes["driver_type"].unique():
        ids = set(episodes[episodes["driver_type"] == type_name]["episode_id"])
        model = population.types[list(population.names).index(type_name)].model
        mine = true[true["episode_id"].isin(ids)].reset_index(drop=True)
        direct = refiltered(roads[roads["episode_id"].isin(ids)], model, town)
        assert np.allclose(np.stack(mine["belief_after"].to_numpy()),
                           np.stack(direct["belief_after"].to_numpy()))
    assert len(true) == len(roads)


def test_a_study_whose_filters_agree_defaults_to_the_filter():
    assert default_belief_source({"config": {"conditions": ["aware", "free"]}}) == "filter"
    assert default_belief_source({"config": {"conditions": ["robust", "free"]}}) == "reference"


@pytest.mark.slow
def test_the_report_heading_names_the_leading_source(robust_study):
    from trustroute.harness.cli import cli as main

    result = CliRunner().invoke(main, ["analyze", str(robust_study)])
    assert result.exit_code == 0, result.output
    heading = (robust_study / "report.md").read_text().split("## Study")[0]
    assert "Leading belief source: 'reference'" in heading and "default for this study" in heading
    assert "Leading belief source: 'reference'" in html.unescape((robust_study / "report.html").read_text())
    result = CliRunner().invoke(main, ["analyze", str(robust_study), "--belief-source", "reported"])
    assert result.exit_code == 0, result.output
    heading = (robust_study / "report.md").read_text().split("## Study")[0]
    assert "Leading belief source: 'reported'" in heading and "default is 'reference'" in heading
    assert "satisfaction on beliefs from: reported" in result.output
