"""EM over a mixture of driver types recovers planted types; one type is `trustroute fit` exactly.

Planted data: 30 participants, each of one of two types of the packaged three-type example
("builder", weight 0.6, and "wary", weight 0.4: the wary type takes over at pedestrians with
probability ~0.97 against ~0.52), 3 model-engine episodes of 30 junctions on random routes each,
reports with accuracy 0.9. Stated tolerances (each far from what a wrong fit gives):
- BIC (n = participants) picks K = 2 among K = 1..3 (types sharing their trust dynamics);
- at K = 2, after the best matching of fitted to planted types, at least 28 of 30 participants
  are assigned to their true type, each weight is within 0.08 (two participants of 30, plus soft
  responsibilities) of the planted type's share of the
  participants, and the pedestrian takeover probability at the type's most visited trust level
  (>= 40 expected visits, so 0.15 is about 2 SE or more) is within 0.15 of the planted one, and
  at least one type's is 0.3 or more from the other planted type's;
- with full types (K = 2 given) the same assignment tolerance holds.
One random start per K is enough here (each K >= 2 also starts from a split of the K-1 fit): the
planted types are far apart, and an E-step that ignores the likelihood or credits episodes to the
wrong participant, or a lighter or heavier BIC penalty, each fail these tests at that size.
"""

from __future__ import annotations

import itertools
import json

import numpy as np
import pandas as pd
import pytest

from tests.analysis.fitting.test_driver_model import RandomRoutes
from trustroute.analysis.fitting.driver_model import fit_em, observations_from_roads
from trustroute.analysis.fitting.mixture import (
    EMSettings,
    ParticipantObservations,
    fit_mixture,
    participant_index,
    select_types,
    study_observations,
)
from trustroute.harness.cli import main
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import run_model_episode
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec

PARTICIPANTS = 30
EPISODES_EACH = 3
PLANTED = {"builder": 0.6, "wary": 0.4}


def _planted_logs(town, seed: int):
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    models = {t.name: t.model for t in population.types}
    rng = np.random.default_rng(seed)
    names = list(PLANTED)
    truth = rng.choice(len(names), size=PARTICIPANTS, p=list(PLANTED.values()))
    spec = load_spec("specs/phi2_strict.toml", town)
    frames, rows = [], []
    for p in range(PARTICIPANTS):
        model = models[names[truth[p]]]
        setup = EpisodeSetup(town=town, driver_model=model, spec=spec, junction_cap=30, fallback_after=None)
        for e in range(EPISODES_EACH):
            episode_id = f"p{p:03d}-e{e}"
            frames.append(run_model_episode(setup, RandomRoutes(town, rng), SyntheticDriver(model, rng, 0.9),
                                            episode_id, 0).roads)
            rows.append({"episode_id": episode_id, "participant": p})
    roads = pd.concat(frames, ignore_index=True).drop(columns=["trust_before", "trust_after"])
    return roads, pd.DataFrame(rows), truth, [models[n] for n in names]


def _matched(fit, truth, planted_models):
    """The permutation of fitted types onto planted ones that assigns most participants correctly."""
    assigned = fit.responsibilities.argmax(axis=1)
    best = max(itertools.permutations(range(fit.n_types)),
               key=lambda perm: int((np.array(perm)[assigned] == truth).sum()))
    return np.array(best), int((np.array(best)[assigned] == truth).sum())


@pytest.fixture(scope="module")
def planted(town):
    roads, episodes, truth, models = _planted_logs(town, seed=21)
    obs = observations_from_roads(roads, models[0])
    owner, ids = participant_index(obs, episodes)
    return ParticipantObservations(obs, owner, ids, models[0]), truth, models


@pytest.mark.slow
def test_bic_picks_the_planted_number_of_types_and_em_recovers_them(planted):
    data, truth, models = planted
    template = models[0]
    selection = select_types(data, 3, np.random.default_rng(2), EMSettings(restarts=1, shared_dynamics=True))
    bics = [f.bic for f in selection.fits]
    assert selection.chosen == 2, f"BIC {bics}"
    fit = selection.best
    assert fit.converged
    perm, correct = _matched(fit, truth, models)
    assert correct >= PARTICIPANTS - 2
    shares = np.bincount(truth, minlength=2) / PARTICIPANTS
    pedestrian = template.incident_types.index("pedestrian")
    separations = []
    for fitted, planted_index in enumerate(perm):
        assert abs(fit.weights[fitted] - shares[planted_index]) <= 0.08
        visits = fit.components[fitted].takeover_weight[pedestrian]
        level = int(np.argmax(visits))
        assert visits[level] >= 40
        error = abs(fit.components[fitted].parameters.takeover[pedestrian, level]
                    - models[planted_index].takeover_probability[pedestrian, level])
        assert error <= 0.15
        other = models[1 - planted_index].takeover_probability[pedestrian, level]
        separations.append(abs(fit.components[fitted].parameters.takeover[pedestrian, level] - other))
    # the fitted types are far from the wrong planted type where they are checked
    assert max(separations) >= 0.3


@pytest.mark.slow
def test_full_types_assign_participants_to_their_planted_type(planted):
    data, truth, models = planted
    fit = fit_mixture(data, 2, np.random.default_rng(5), EMSettings(restarts=1))
    assert fit.converged
    _, correct = _matched(fit, truth, models)
    assert correct >= PARTICIPANTS - 2
    # a single type cannot separate them: the 2-type likelihood is far higher
    single = fit_mixture(data, 1, np.random.default_rng(5))
    assert fit.loglik - single.loglik > 100


def test_one_type_is_exactly_trustroute_fit(model_study):
    data, _ = study_observations(model_study)
    single = fit_em(data.observations, data.template, 200)
    mixture = fit_mixture(data, 1, np.random.default_rng(0), EMSettings(iterations=200))
    assert mixture.iterations == single.iterations
    assert mixture.loglik == pytest.approx(single.loglik, rel=1e-12, abs=1e-9)
    component = mixture.components[0].parameters
    for name in ("initial", "takeover", "failure", "transition"):
        np.testing.assert_allclose(getattr(component, name), getattr(single.parameters, name),
                                   rtol=1e-10, atol=1e-12)
    assert mixture.report_accuracy == single.report_accuracy
    np.testing.assert_allclose(mixture.responsibilities, 1.0)


@pytest.mark.slow
def test_fit_types_cli_writes_a_population_with_a_bic_table(model_study, tmp_path, capsys):
    out = tmp_path / "types.json"
    with pytest.raises(SystemExit) as exit_info:
        main([
            "fit", str(model_study), "--types", "auto", "--max-types", "2", "--restarts", "1",
            "--iterations", "20", "--bootstrap", "1", "--seed", "3", "--out", str(out), "--json",
        ])
    assert exit_info.value.code == 0
    payload = json.loads(capsys.readouterr().out)
    population = load_driver_population(out)
    assert population.n_types == payload["types"] in (1, 2)
    assert [row["types"] for row in payload["bic_table"]] == [1, 2]
    chosen = min(payload["bic_table"], key=lambda row: row["bic"])["types"]
    assert chosen == payload["types"]
    assert sum(payload["bootstrap"]["chosen_types_frequency"].values()) == 1
    assert "trustroute fit" in population.provenance and "BIC" in population.provenance
    assert set(payload["paths"]) == {"population", "fit_details"}
    assert json.loads((tmp_path / "types.fit.json").read_text())["types"] == payload["types"]


@pytest.mark.parametrize("types", ["0", "many", "21"])
def test_fit_types_rejects_a_bad_count(model_study, tmp_path, capsys, types):
    with pytest.raises(SystemExit) as exit_info:
        main(["fit", str(model_study), "--types", types, "--out", str(tmp_path / "t.json")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--types" in err and "Traceback" not in err


def test_committed_real_population_is_reproduced_by_the_one_type_fit():
    from pathlib import Path

    from trustroute.analysis.fitting.driver_model import fit_study

    data = Path(__file__).resolve().parents[3] / "participants" / "data"
    population = load_driver_population(data / "driver_population_real.json")
    details = json.loads((data / "driver_population_real.fit.json").read_text())
    table = details["bic_table"]
    assert population.n_types == details["types"] == min(table, key=lambda r: r["bic"])["types"]
    assert details["bootstrap"]["resamples"] == sum(details["bootstrap"]["chosen_types_frequency"].values())
    if population.n_types == 1:  # then it is `trustroute fit` on the same logs
        study = Path(__file__).resolve().parents[3] / "analysis" / "data" / "real_study" / "study"
        refit = fit_study(study, method="em").model()
        model = population.types[0].model
        np.testing.assert_allclose(model.takeover_probability, refit.takeover_probability, atol=1e-12)
        np.testing.assert_allclose(model.trust_transition, refit.trust_transition, atol=1e-12)
        np.testing.assert_allclose(model.initial_belief, refit.initial_belief, atol=1e-12)


def test_fit_a_given_number_of_types(model_study, tmp_path, capsys):
    out = tmp_path / "two.json"
    with pytest.raises(SystemExit) as exit_info:
        main(["fit", str(model_study), "--types", "2", "--restarts", "1", "--iterations", "30",
              "--bootstrap", "1", "--seed", "1", "--out", str(out), "--json"])
    assert exit_info.value.code == 0
    payload = json.loads(capsys.readouterr().out)
    population = load_driver_population(out)
    assert population.n_types == payload["types"] == 2 and "bic_table" not in payload
    assert population.weights.sum() == pytest.approx(1.0, abs=1e-9)
    assert set(payload["bootstrap"]["weights"]) == set(population.names)
    assert payload["fit"]["iterations"] <= 30
