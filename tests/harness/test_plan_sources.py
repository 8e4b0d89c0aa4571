"""`trustroute plan` judges satisfaction as the study's analysis will: on the study's primary belief
source (harness/study/planning.py `source_satisfied`). Drivers of the three packaged types under
aware, robust and free: each AV's own filter ("filter") calls about 0.95 of the aware episodes
satisfied where each driver's own model ("true", the neutral default) calls about 0.55, so a plan
on the AV's filter would size a study for an effect its analysis does not see.
(Horizon 3 keeps synthesis fast, as in tests/analysis/study/test_belief_sources.py; at that horizon
aware and robust are their fallback, which the sources judge apart just as well.)"""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli import cli_json
from tests.conftest import shared_fixture
from tests.robust_study_config import robust_study_text
from trustroute.analysis.study.analysis import study_analysis
from trustroute.harness.study.config import BELIEF_SOURCES, load_study_config
from trustroute.harness.study.context import study_context
from trustroute.harness.study.planning import ParticipantModel, simulate_studies
from trustroute.harness.study.runner import run_and_consolidate
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population

STUDY_PARTICIPANTS, PLANNED_PARTICIPANTS = 240, 1200


def _build(root):
    (root / "plan.toml").write_text(robust_study_text(root, STUDY_PARTICIPANTS, drivers=False))
    (root / "study.toml").write_text(robust_study_text(root, STUDY_PARTICIPANTS))
    run_and_consolidate(load_study_config(root / "study.toml"), root / "out", 1, None, progress=False,
                        echo=lambda *_: None)


@pytest.fixture(scope="module")
def configs(temporary_cache):
    """(the config a plan reads, a study of that config with the types as its drivers): built once
    per run (tests/conftest.py, `shared_fixture`), only read by the tests."""
    root = shared_fixture(temporary_cache, "plan-sources", _build)
    return root / "plan.toml", root / "out"


@pytest.mark.slow
@pytest.mark.parametrize("source", BELIEF_SOURCES)
def test_planned_satisfaction_is_the_analysis_on_each_source(configs, source):
    plan_config, study = configs
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    types = ParticipantModel(label="types", types=tuple(t.model for t in population.types),
                             weights=tuple(population.weights))
    sims = simulate_studies(study_context(load_study_config(plan_config)), PLANNED_PARTICIPANTS, 1,
                            np.random.default_rng(2), types, source)
    planned = sims.satisfied.mean(axis=(0, 1))[0]
    analysed = study_analysis(study, belief_source=source, resamples=10).cells["satisfaction_rate"].to_numpy()
    # two independent samples of the same rates: within 4 standard errors of their difference
    p = (planned + analysed) / 2
    tolerance = 4 * np.sqrt(p * (1 - p) * (1 / PLANNED_PARTICIPANTS + 1 / STUDY_PARTICIPANTS))
    assert np.all(np.abs(planned - analysed) <= tolerance), (source, planned, analysed, tolerance)


def test_the_plan_names_the_source_it_judges_on(configs, capsys, tmp_path):
    plan_config, _ = configs
    answer = cli_json(capsys, "plan", str(plan_config), "--participants", "6", "--simulations", "10",
                      "--test", "mcnemar", "--out", str(tmp_path),
                      "--preregistration", str(tmp_path / "p.md"))
    assert answer["belief_source"] == "true"   # the neutral default of a simulated study
    assert "satisfaction judged on beliefs from: true" in (tmp_path / "p.md").read_text()
    declared = tmp_path / "declared.toml"
    declared.write_text(plan_config.read_text().replace('engine = "model"',
                                                        'engine = "model"\nbelief_source = "reported"'))
    answer = cli_json(capsys, "plan", str(declared), "--participants", "6", "--simulations", "10",
                      "--test", "mcnemar", "--out", str(tmp_path))
    assert answer["belief_source"] == "reported"


def test_the_avs_own_model_judges_as_the_av(model_study):
    """Participants who are the config's driver model, judged by that model's exact filter
    ("true"): the plan takes the AV's own verdict without a trace, and the full evaluation (the same
    model as another object, so traced) gives that verdict."""
    from dataclasses import replace

    from trustroute.harness.simulation.model_engine import simulate_batch
    from trustroute.harness.study.planning import is_own_verdict, source_satisfied

    context = study_context(load_study_config(model_study.parent / "study.toml"))
    twin = replace(context.nominal)   # equal, not identical: judged through the trace
    for cell in [(spec, condition) for spec in ("phi1", "phi2") for condition in ("aware", "free")]:
        setup = context.setup(*cell)
        assert is_own_verdict("true", context, setup, [context.nominal])
        assert not is_own_verdict("true", context, setup, [twin])
        result = simulate_batch(setup, context.policies[cell], 4000, np.random.default_rng(1), trace=True,
                                report_accuracy=0.8)
        judged = source_satisfied("true", context, cell, setup, result,
                                  ([twin], np.zeros(4000, dtype=np.int64)))
        np.testing.assert_array_equal(judged, result.satisfied)


def test_the_power_curve_names_the_source(configs, tmp_path, monkeypatch):
    import trustroute.app.planning as planning

    titles = []
    real = planning.power_curve_plot
    monkeypatch.setattr(planning, "power_curve_plot",
                        lambda *args, title="", **kw: titles.append(title) or real(*args, title=title, **kw))
    planning.plan_study(configs[0], planning.PlanSettings(sizes="6", simulations=10, tests=("mcnemar",),
                                                          out=str(tmp_path)))
    assert "satisfaction on beliefs from: true" in titles[0] and "grey dotted: α" in titles[0]
