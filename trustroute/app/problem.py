"""The compiled problem of a run, built once from its inputs and passed down: the town, the AV's
model (a population's type-aware model, its spec lifted onto it), the trust POMDP and the case
(policies/belief/problem.py). The one initial-trust check is here too."""

from __future__ import annotations

from trustroute.app.inputs import Inputs, PathLike, load_inputs
from trustroute.core.errors import InputError
from trustroute.core.fields import is_whole
from trustroute.core.wording import shown_value
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.belief.problem import Problem, problem
from trustroute.policies.logic.spec import Spec


def compile_problem(inputs: Inputs) -> Problem:
    """The Problem of `inputs`: one driver model, or a population lifted to its type-aware model
    and spec."""
    if inputs.population is not None:
        return problem(inputs.town, inputs.population, inputs.spec, inputs.population_source)
    return problem(inputs.town, inputs.model, inputs.spec)


def check_initial_trust(model: DriverModel, initial_trust: int | None,
                        option: str = "--initial-trust") -> None:
    """A given initial trust is a trust level of `model`, a whole number as the CLI's is (True and
    1.0 are not); an InputError naming `option` otherwise."""
    if initial_trust is None:
        return
    if not (is_whole(initial_trust) and initial_trust in model.trust_levels):
        raise InputError(option, "", f"{shown_value(initial_trust)} is not a trust level of the model",
                         f"pass one of {list(model.trust_levels)}")


def load_problem(spec: Spec | PathLike, town: Town | PathLike | None = None,
                 driver: DriverModel | PathLike | None = None,
                 population: DriverPopulation | PathLike | None = None) -> Problem:
    """The compiled problem of inputs given by object, path or packaged name (`load_inputs`)."""
    return compile_problem(load_inputs(spec, town, driver, population))
