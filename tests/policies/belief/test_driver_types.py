"""The type-aware POMDP: one type is today's model; the lifted filter is the exact joint filter;
the online type posterior finds the true type on long drives; type-belief atoms."""

from __future__ import annotations

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from trustroute.core.errors import InputError
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.driver_population import (
    EXAMPLE_POPULATION_PATH,
    DriverPopulation,
    DriverType,
    load_driver_population,
    single_type_population,
)
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.belief.driver_types import (
    lift_population,
    lift_spec,
    trust_marginal,
    type_belief,
)
from trustroute.policies.logic.spec import load_spec, spec_from_text
from trustroute.policies.model.trust_pomdp import build_pomdp

INCIDENTS = ("obstacle", "pedestrian", "truck", "none")


def test_one_type_is_the_model_and_the_spec_itself(town):
    model = load_driver_model()
    population = single_type_population(model)
    assert lift_population(population) is model
    spec = load_spec("specs/phi1.toml", town)
    assert lift_spec(spec, population) is spec


def test_lifted_filter_equals_one_unnormalised_filter_per_type():
    """After random observations the lifted posterior's type and trust marginals equal those of
    K separate filters on the types' own arrays, weighted by the prior and the likelihoods."""
    rng = np.random.default_rng(5)
    models = [random_driver(rng, INCIDENTS) for _ in range(3)]
    weights = np.array([0.5, 0.2, 0.3])
    population = DriverPopulation(tuple(DriverType(f"t{j}", float(w), m)
                                        for j, (w, m) in enumerate(zip(weights, models, strict=True))))
    from trustroute.networks.town import load_town

    pomdp = build_pomdp(load_town(None), lift_population(population))
    belief = np.asarray(pomdp.initial_belief, dtype=float)
    alpha = np.stack([w * m.initial_belief for w, m in zip(weights, models, strict=True)])
    for _ in range(25):
        incident, h, e = int(rng.integers(3)), int(rng.integers(2)), int(rng.integers(2))
        posterior, probability = pomdp.belief_update(belief, incident, h, e)
        for k, m in enumerate(models):
            p_h = m.takeover_probability[incident] if h else 1 - m.takeover_probability[incident]
            p_e = m.failure_probability[incident] if e else 1 - m.failure_probability[incident]
            alpha[k] = (alpha[k] * p_h * p_e) @ m.trust_transition[incident, h, e]
        assert probability[0] == pytest.approx(alpha.sum(), rel=1e-9)
        alpha /= alpha.sum()
        belief = posterior[0]
        np.testing.assert_allclose(type_belief(pomdp.driver, belief), alpha.sum(axis=1), atol=1e-12)
        np.testing.assert_allclose(trust_marginal(pomdp.driver, belief), alpha.sum(axis=0), atol=1e-12)
    levels = np.asarray(pomdp.driver.trust_levels, dtype=float)
    assert belief @ levels == pytest.approx(alpha.sum(axis=0) @ np.arange(1, 8), rel=1e-12)


@pytest.mark.parametrize("true_type", ["builder", "flat", "wary"])
def test_online_type_posterior_converges_to_the_true_type(town, true_type):
    """Seeded drives of 400 incident roads (uniform among the town's incident kinds) with a driver
    of each example type: the AV's type posterior ends above 0.95 on the true type in at least 9 of
    10 drives, and its mean over the drives is above 0.95."""
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    pomdp = build_pomdp(town, lift_population(population))
    k = population.type_index(true_type)
    incidents = [i for i in ("obstacle", "pedestrian", "truck")]
    finals = []
    for seed in range(10):
        rng = np.random.default_rng([seed, k])
        driver = SyntheticDriver(population.types[k].model, rng)
        belief = np.asarray(pomdp.initial_belief, dtype=float)
        for _ in range(400):
            incident = incidents[int(rng.integers(len(incidents)))]
            took_over = driver.decides_takeover(incident)
            performance = driver.performance(incident)
            driver.move_trust(incident, took_over, performance)
            posterior, _ = pomdp.belief_update(belief, pomdp.driver.incident_index(incident),
                                               int(took_over), int(performance == "fail"))
            belief = posterior[0]
        finals.append(type_belief(pomdp.driver, belief)[k])
    finals = np.array(finals)
    assert (finals > 0.95).sum() >= 9, finals
    assert finals.mean() > 0.95, finals


def test_type_belief_atom_is_a_belief_atom_on_the_type_blocks(town):
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    text = ('name = "t"\nstart = "E-A"\nformula = "F (v1 & nontruster)"\n[states]\nv1 = ["B-G"]\n'
            '[beliefs.high]\ncoeffs = [0, 0, 0, 0, 0, 1, 1]\noffset = 0.5\n'
            '[type_beliefs]\nnontruster = { types = ["flat", "wary"], above = 0.7 }\n')
    spec = spec_from_text(text, "t.toml", town)
    assert spec.type_atoms["nontruster"].types == ("flat", "wary")
    lifted = lift_spec(spec, population)
    atom = lifted.belief_atoms["nontruster"]
    assert atom.coeffs == (0.0,) * 7 + (1.0,) * 14 and atom.offset == 0.7
    assert lifted.belief_atoms["high"].coeffs == (0, 0, 0, 0, 0, 1, 1) * 3
    assert not lifted.type_atoms
    assert spec.content_hash != spec_from_text(text.replace("0.7", "0.6"), "t.toml", town).content_hash


def test_a_type_the_population_lacks_names_both_files(town):
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    text = ('name = "t"\nstart = "E-A"\nformula = "F (v1 & sure)"\n[states]\nv1 = ["B-G"]\n'
            '[type_beliefs]\nsure = { types = ["stubborn"], above = 0.5 }\n')
    spec = spec_from_text(text, "t.toml", town)
    with pytest.raises(InputError) as info:
        lift_spec(spec, population, "pop.json")
    message = info.value.one_line()
    assert "t.toml" in message and "pop.json" in message and "stubborn" in message


@pytest.mark.parametrize("entry, problem", [
    ('sure = { types = [], above = 0.5 }', "non-empty list"),
    ('sure = { types = ["a"], above = 1.0 }', "in [0, 1)"),
    ('sure = { types = ["a"] }', "missing 'above'"),
    ('sure = { types = ["a"], above = 0.5, below = 0.2 }', "unknown key 'below'"),
    ('v1 = { types = ["a"], above = 0.5 }', "defined twice"),
])
def test_bad_type_belief_atoms(town, entry, problem):
    text = ('name = "t"\nstart = "E-A"\nformula = "F v1"\n[states]\nv1 = ["B-G"]\n'
            f'[type_beliefs]\n{entry}\n')
    with pytest.raises(InputError, match=problem.replace("[", r"\[").replace(")", r"\)")):
        spec_from_text(text, "t.toml", town)


def test_lint_reads_type_belief_atoms_with_and_without_a_population(town):
    from trustroute.policies.logic.lint import lint

    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    text = ('name = "t"\nstart = "E-A"\nformula = "F (v1 & nontruster)"\n[states]\nv1 = ["B-G"]\n'
            '[type_beliefs]\nnontruster = { types = ["flat"], above = 0.7 }\n')
    spec = spec_from_text(text, "t.toml", town)
    assert "type-belief-unchecked" in {w.code for w in lint(spec, town)}
    lifted = lint(lift_spec(spec, population), town, driver=lift_population(population))
    assert "type-belief-unchecked" not in {w.code for w in lifted}
    assert "unused-atom" not in {w.code for w in lifted}
