"""A routing problem, Problem(town, driver or population, spec), and which case it is, decided once.

The case says what the AV must track and so which synthesis, evaluation node state and episode
tracking apply (docs/trust_states.md, docs/driver_types.md):

- PLAIN: one driver model; the spec's DFA state is a function of the observations (observed DFA):
  belief-MDP synthesis (policies/synthesis), the observed node state of the exact evaluation, the
  episode's DFA stepped on (road, belief).
- TRUST_STATE: a formula that tests the hidden trust: the DFA state is hidden and the AV tracks
  the joint law J(θ, q) (policies/belief/trust_state_filter.py): the trust-state search
  (policies/trust_state_synthesis), the hidden node state, the joint filter in episodes. With a
  population of several types θ is the type-aware model's hidden (type, trust) index, so J is
  over ((type, trust), q) and its blocks give every type's value
  (policies/evaluation/trust_state.py, `evaluate_joint_by_type`); its population policies come
  from the trust-state search on the lifted model (policies/trust_state_synthesis/population.py).
- DRIVER_TYPES: a population of several driver types and a spec without trust-state atoms: the
  AV's model is the type-aware one over (type, trust) and the spec is lifted onto it
  (policies/belief/driver_types.py); its DFA state is observed, so everything runs as PLAIN on
  the lifted model.

A population of one type is the single-model problem of the type's own model and spec (bit for
bit). Callers ask `case_of` or `Problem.case` rather than testing the spec or the model.
"""

from __future__ import annotations

from dataclasses import dataclass

from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.belief.driver_types import lift_population, lift_spec, n_types_of
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP, build_pomdp

PLAIN, TRUST_STATE, DRIVER_TYPES = "plain", "trust-state", "driver-types"
CASES: tuple[str, ...] = (PLAIN, TRUST_STATE, DRIVER_TYPES)


def reads_hidden_trust(spec: Spec) -> bool:
    """Whether the spec's labels read the human's hidden trust (trust-state atoms): the DFA state
    is then hidden from the AV, and a logged trace needs its trust levels to be judged."""
    return spec.uses_trust_atoms


def case_of(driver: DriverModel, spec: Spec) -> str:
    """The case of the problem whose AV model is `driver` (the type-aware one for a population)
    and whose spec (as the AV reads it) is `spec`."""
    if reads_hidden_trust(spec):
        return TRUST_STATE
    return DRIVER_TYPES if n_types_of(driver) > 1 else PLAIN


def dfa_is_hidden(driver: DriverModel, spec: Spec) -> bool:
    """Whether the AV cannot observe the spec's DFA state (it tracks J(θ, q) instead)."""
    return case_of(driver, spec) == TRUST_STATE


@dataclass(frozen=True, eq=False)
class Problem:
    """A town, the AV's driver model and trust POMDP, the spec as the AV reads it, and the case.

    For a population: `driver` is its type-aware model, `spec` the lifted spec, `population` the
    population and `given_spec` the spec as given; otherwise `given_spec` is `spec`."""

    town: Town
    driver: DriverModel
    spec: Spec
    pomdp: TrustPOMDP
    case: str
    given_spec: Spec
    population: DriverPopulation | None = None

    @property
    def dfa_hidden(self) -> bool:
        return self.case == TRUST_STATE


def problem(town: Town, driver: DriverModel | DriverPopulation, spec: Spec,
            population_source: str = "", pomdp: TrustPOMDP | None = None) -> Problem:
    """The problem of routing on `town` for `spec` with one driver model or a driver population
    (`population_source`: the population's file, for messages); `pomdp`: the AV's trust POMDP
    when already built."""
    if isinstance(driver, DriverPopulation):
        model, lifted = lift_population(driver), lift_spec(spec, driver, population_source)
        return Problem(town=town, driver=model, spec=lifted,
                       pomdp=pomdp if pomdp is not None else build_pomdp(town, model),
                       case=case_of(model, lifted), given_spec=spec, population=driver)
    return Problem(town=town, driver=driver, spec=spec,
                   pomdp=pomdp if pomdp is not None else build_pomdp(town, driver),
                   case=case_of(driver, spec), given_spec=spec)


def problem_of(pomdp: TrustPOMDP, spec: Spec) -> Problem:
    """The problem of a trust POMDP (its town and AV model) and the spec the AV reads."""
    return problem(pomdp.town, pomdp.driver, spec, pomdp=pomdp)
