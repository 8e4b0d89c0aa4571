"""A neutral primary belief source for every condition compared: a study of the three packaged
driver types with the `robust` condition (whose AV filters with the type-aware model, the
"reference" filter) beside `aware` and `free` (the nominal filter) is judged by default on each
driver's own exact filter ("true"), which is no condition's own; the API and the CLI share that
default; every pair of conditions is tested with Holm-adjusted p-values; the sensitivity table shows
every comparison on every source; the report says which source leads.
(Horizon 3 keeps synthesis fast, as in tests/harness/test_study_robust.py.)"""

from __future__ import annotations

import html

import numpy as np
import pytest
from click.testing import CliRunner

from tests.conftest import shared_fixture
from tests.robust_study_config import robust_study_text
from trustroute.analysis.belief_sources import (
    default_belief_source,
    refiltered,
    true_roads,
)
from trustroute.analysis.study.analysis import study_analysis
from trustroute.analysis.study_directory import load_study, study_inputs
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.context import reference_model
from trustroute.harness.study.runner import run_and_consolidate
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.policies.belief.driver_types import TypeLiftedModel


def _build(root):
    path = root / "study.toml"
    path.write_text(robust_study_text(root, 6))
    run_and_consolidate(load_study_config(path), root / "out", 1, None, progress=False, echo=lambda *_: None)


@pytest.fixture(scope="module")
def robust_study(temporary_cache):
    """Built once per run (tests/conftest.py, `shared_fixture`); of its tests, only the report
    heading's writes into it (its report), and no other test reads the report."""
    return shared_fixture(temporary_cache, "belief-sources", _build) / "out"


@pytest.fixture(scope="module")
def default_analysis(robust_study):
    """The study's analysis on its default source, read (never changed) by several tests."""
    return study_analysis(robust_study, resamples=50)


@pytest.mark.slow
def test_the_default_source_is_neutral_to_every_condition(robust_study, default_analysis):
    manifest, episodes, roads = load_study(robust_study)
    assert default_belief_source(manifest) == "true"
    analysis = default_analysis
    assert analysis.belief_source == "true" and analysis.source_note == ""
    town, driver, _ = study_inputs(manifest, robust_study)
    model = reference_model(manifest["config"], driver)
    assert isinstance(model, TypeLiftedModel) and model.n_types == 3
    reference = refiltered(roads, model, town).set_index(["episode_id", "index"])["belief_after"]
    logged = roads.set_index(["episode_id", "index"])["belief_after"].loc[reference.index]
    condition = reference.index.get_level_values(0).map(
        dict(zip(episodes["episode_id"], episodes["condition"], strict=True)))
    reference_b, logged_b = np.stack(reference.to_numpy()), np.stack(logged.to_numpy())
    # the robust AV's own filter is the reference filter: identical beliefs on its roads, so
    # "reference" scores the robust condition on its own belief and is not neutral ...
    robust = np.asarray(condition == "robust")
    assert np.allclose(reference_b[robust], logged_b[robust], atol=1e-12)
    # ... while the aware AV's own (nominal) filter differs from it, so "filter" is not common
    aware = np.asarray(condition == "aware")
    assert not np.allclose(reference_b[aware], logged_b[aware], atol=1e-6)
    # every condition's satisfaction on the default source is that of each driver's true filter
    assert {"satisfied_filter", "satisfied_reported", "satisfied_reference", "satisfied_true"} <= set(
        analysis.episodes.columns)
    assert analysis.cells["satisfied"].tolist() == [
        int(analysis.episodes[analysis.episodes["condition"] == c]["satisfied_true"].sum())
        for c in analysis.cells["condition"]]


@pytest.mark.slow
def test_the_api_and_the_cli_share_the_default(robust_study):
    import json

    import trustroute
    from trustroute.harness.cli import cli as main

    api = trustroute.analyze(robust_study)
    result = CliRunner().invoke(main, ["analyze", str(robust_study), "--json"])
    assert result.exit_code == 0, result.output
    cli = json.loads(result.output)
    assert api.belief_source == cli["belief_source"] == "true"
    assert api.to_dict()["cells"] == cli["cells"] and api.to_dict()["paired"] == cli["paired"]


@pytest.mark.slow
def test_every_pair_of_conditions_is_tested_with_holm(default_analysis):
    analysis = default_analysis
    pairs = set(zip(analysis.paired["condition_a"], analysis.paired["condition_b"], strict=True))
    assert pairs == {("aware", "robust"), ("aware", "free"), ("robust", "free")}
    assert (analysis.paired["spec"] == "phi1").sum() == 3
    for test in ("mcnemar_p", "wilcoxon_p"):
        raw, adjusted = analysis.paired[test], analysis.paired[f"{test}_holm"]
        assert all(a is None or a >= r - 1e-12 for r, a in zip(raw, adjusted, strict=True))
    effects = set(analysis.repeated["effect_of"])
    assert effects == {"aware vs robust", "aware vs free", "robust vs free"}
    assert "p_value_holm" in analysis.repeated
    assert set(analysis.per_participant.columns) >= {f"satisfied_{c}" for c in ("aware", "robust", "free")}
    assert "Holm" in analysis.to_dict()["multiplicity"]


@pytest.mark.slow
def test_the_sensitivity_table_shows_every_comparison_on_every_source(robust_study, default_analysis):
    from trustroute.analysis.study.display import display_tables

    analysis = default_analysis
    table = analysis.sensitivity
    assert set(table["source"]) == {"filter", "reported", "reference", "true"}
    assert set(table.loc[table["primary"], "source"]) == {"true"}
    for source, rows in table.groupby("source"):
        assert len(rows) == len(analysis.paired), source
    primary = table[table["primary"]].reset_index(drop=True)
    assert primary["risk_difference"].tolist() == analysis.paired["risk_difference"].tolist()
    # another source's figures are those of an analysis led by it
    filtered = study_analysis(robust_study, "filter", resamples=50)
    assert (table.loc[table["source"] == "filter", "risk_difference"].tolist()
            == filtered.paired["risk_difference"].tolist())
    shown = display_tables(analysis)["sensitivity"]
    assert list(shown.columns) == ["pair", "spec", "filter", "reported", "reference", "true (primary)"]


@pytest.mark.slow
def test_true_source_filters_with_each_drivers_type(robust_study):
    manifest, episodes, roads = load_study(robust_study)
    town, driver, _ = study_inputs(manifest, robust_study)
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    true = true_roads(robust_study, manifest, roads, episodes, driver, town)
    for type_name in episodes["driver_type"].unique():
        ids = set(episodes[episodes["driver_type"] == type_name]["episode_id"])
        model = population.types[list(population.names).index(type_name)].model
        mine = true[true["episode_id"].isin(ids)].reset_index(drop=True)
        direct = refiltered(roads[roads["episode_id"].isin(ids)], model, town)
        assert np.allclose(np.stack(mine["belief_after"].to_numpy()),
                           np.stack(direct["belief_after"].to_numpy()))
    assert len(true) == len(roads)


def test_the_default_is_true_in_simulation_and_reported_for_people():
    def default(engine: str, conditions: list[str]) -> str:
        return default_belief_source({"engine": engine, "config": {"conditions": conditions}})

    assert default("model", ["aware", "free"]) == default("sumo", ["robust", "free"]) == "true"
    assert default("live", ["aware", "free"]) == "reported"
    assert default_belief_source({"engine": "carla-logs", "config": {}}) == "reported"
    declared = {"engine": "model", "config": {"conditions": ["aware", "free"], "belief_source": "filter"}}
    assert default_belief_source(declared) == "filter"


def test_a_config_declares_its_primary_source(tmp_path):
    from trustroute.core.errors import InputError
    from trustroute.harness.study.config import study_config_from_dict

    study = {"participants": 2, "seed": 1, "engine": "model", "specs": ["phi1"],
             "conditions": ["aware", "free"]}
    plain = study_config_from_dict({"study": study})
    declared = study_config_from_dict({"study": {**study, "belief_source": "reported"}})
    assert plain.belief_source is None and declared.belief_source == "reported"
    assert plain.content_hash != declared.content_hash   # pre-registered: part of the study's identity
    with pytest.raises(InputError, match="belief_source"):
        study_config_from_dict({"study": {**study, "belief_source": "own"}})
    with pytest.raises(InputError, match="simulated drivers"):
        study_config_from_dict({"study": {**study, "engine": "live", "belief_source": "true"}})


@pytest.mark.slow
def test_the_report_heading_names_the_leading_source(robust_study):
    from trustroute.harness.cli import cli as main

    result = CliRunner().invoke(main, ["analyze", str(robust_study)])
    assert result.exit_code == 0, result.output
    report = (robust_study / "report.md").read_text()
    heading = report.split("## Study")[0]
    assert "Leading belief source: 'true'" in heading and "neutral default" in heading
    assert "Leading belief source: 'true'" in html.unescape((robust_study / "report.html").read_text())
    assert "## Sensitivity" in report and "Multiplicity: Holm" in report
    assert "Paired effects over participants (beliefs: true)" in result.output
    result = CliRunner().invoke(main, ["analyze", str(robust_study), "--belief-source", "reported"])
    assert result.exit_code == 0, result.output
    heading = (robust_study / "report.md").read_text().split("## Study")[0]
    assert "Leading belief source: 'reported'" in heading and "primary source is 'true'" in heading
    assert "satisfaction on beliefs from: reported" in result.output
