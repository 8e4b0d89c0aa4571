"""`policy_for(problem, name, settings)`: the routing policy a run drives, by name or file.

Names: "free" (the trust-free shortest route completing the spec's task), "aware" (synthesized for
the AV's model and cached), and for a driver population "robust" or "bayes" (its population policy,
synthesized and cached, docs/driver_types.md); anything else is a policy file. The problem is the
compiled one (trustroute/app/problem.py): a population's policy is made for its given spec and
drives with its type-aware model and lifted spec.
"""

from __future__ import annotations

from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.policies.belief.problem import Problem
from trustroute.policies.resolve import DEFAULT_POLICY, PolicySettings, population_policy, resolve_policy
from trustroute.policies.routing.files import load_population_policy
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy

POPULATION_POLICIES: tuple[str, ...] = ("robust", "bayes")   # objectives of a population policy


def policy_for(problem: Problem, name: str | Path,
               settings: PolicySettings = DEFAULT_POLICY) -> RoutingPolicy:
    """The policy `name` for `problem` ("free", "aware", "robust", "bayes" or a policy file)."""
    name = str(name)
    if problem.population is not None:
        return _population_policy(problem, name, settings)
    if name in POPULATION_POLICIES:
        raise InputError(name, "", f"the policy {name!r} is made for a driver population",
                         "pass --population FILE (or the population= argument), or use 'free' or 'aware'")
    return resolve_policy(name, problem.town, problem.driver, problem.spec, settings.cache_dir,
                          settings.horizon, settings.belief_rule, progress=settings.progress)


def _population_policy(problem: Problem, name: str, settings: PolicySettings) -> RoutingPolicy:
    population = problem.population
    assert population is not None
    source = population.source_path
    if name == "free":
        return trust_free_policy(problem.town, problem.spec)
    if name in POPULATION_POLICIES:
        policy, _, _ = population_policy(problem.town, population, problem.given_spec, name, settings,
                                         population_source=source)
        return policy
    if name == "aware":
        raise InputError(name, "", "with a driver population the policy is 'free', 'robust', 'bayes' or "
                         "a policy file", "pass 'robust' or 'bayes' for the population's own policy, or "
                         "drop --population for the single model's 'aware'")
    if not Path(name).exists():
        raise InputError(name, "", "not a policy file and not 'free', 'robust' or 'bayes'",
                         "pass a policy file written by trustroute synth --population")
    policy, _, _ = load_population_policy(name, problem.town, population, problem.given_spec, source)
    return policy
