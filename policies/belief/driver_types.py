"""The type-aware trust POMDP: a driver population lifted to one trust-like hidden state.

The hidden state is (type k, trust θ). It is encoded as one hidden index i = k·n + θ of a driver
model with K·n "trust" states (docs/driver_types.md, "The lifted model"):

- takeover and failure probabilities: type k's on block k (concatenated over types);
- trust transitions: block-diagonal, type k's matrices on block k (a driver never changes type);
- initial belief: λ ⊗ b0, i.e. λ_k · b0_k on block k (λ the AV's type prior, by default the
  population's weights; b0_k type k's initial trust distribution);
- trust levels: the base levels repeated K times, so Σ_i b_i level_i is the expected trust.

The TrustPOMDP of the lifted model (policies/model/trust_pomdp.py) is then the type-aware POMDP,
and its one Bayes filter is the exact filter over (type, trust), vectorised like any other; every
consumer (synthesis, its bounds, exact evaluation, the episode tracker) runs on it unchanged.

Belief atoms stay defined on the trust marginal: their coefficient vectors are tiled over the
types (c·marginal(b) = tile(c, K)·b). A type-belief atom `P(type ∈ S) > a` is the belief atom with
coefficients 1 on the blocks of S and offset a. `lift_spec` rewrites a spec so (the labeller's
rounding margin γ_{4m+2} is taken with m = K·n, the lifted filter's length).

With one type and the population's own prior, `lift_population` returns the type's model itself
and `lift_spec` the spec itself (when it has no type-belief atoms): everything is the single model's,
bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.core.errors import InputError
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.logic.spec import BeliefAtom, Spec


@dataclass(frozen=True, eq=False)
class TypeLiftedModel(DriverModel):
    """A driver model whose hidden index is (type, trust) = k·n_base + θ (module docstring)."""

    type_names: tuple[str, ...] = ()
    n_base_trust: int = 0
    type_prior: tuple[float, ...] = ()      # λ, the AV's prior over types
    # each type's own initial trust law b0_k: the exact filter builds λ ⊗ b0 from these, as the float
    # products λ_k·b0_k round (0.5·(1/3) is not half of 1/3 in floats)
    type_initial: tuple[tuple[float, ...], ...] = ()
    population_hash: str = ""

    @property
    def n_types(self) -> int:
        return len(self.type_names)


def n_types_of(model: DriverModel) -> int:
    return model.n_types if isinstance(model, TypeLiftedModel) else 1


def base_trust_index(model: DriverModel) -> np.ndarray:
    """int [n_hidden]: the trust level index θ of each hidden index (k·n + θ -> θ for a lifted
    model; the identity for one driver model), what trust-state atoms read."""
    n_hidden = model.n_trust
    return np.arange(n_hidden) % (n_hidden // n_types_of(model))


def check_prior(prior: np.ndarray, population: DriverPopulation, where: str = "prior") -> np.ndarray:
    prior = np.asarray(prior, dtype=float)
    if (prior.shape != (population.n_types,) or not np.all(np.isfinite(prior)) or prior.min() < 0
            or abs(prior.sum() - 1) > 1e-9):
        raise InputError(where, "", f"{prior.tolist()} is not a prior over the "
                         f"{population.n_types} types {list(population.names)}",
                         "give one nonnegative weight per type, summing to 1")
    return prior


def lift_population(population: DriverPopulation, prior: np.ndarray | None = None) -> DriverModel:
    """The driver model of the type-aware POMDP with type prior `prior` (default: the weights).
    One type: the type's model itself."""
    weights = population.weights if prior is None else check_prior(prior, population)
    if population.n_types == 1:
        return population.types[0].model
    models = population.models
    first = models[0]
    k, n = population.n_types, first.n_trust
    takeover = np.concatenate([m.takeover_probability for m in models], axis=1)
    failure = np.concatenate([m.failure_probability for m in models], axis=1)
    n_inc = len(first.incident_types)
    transition = np.zeros((n_inc, 2, 2, k * n, k * n))
    for j, m in enumerate(models):
        transition[..., j * n:(j + 1) * n, j * n:(j + 1) * n] = m.trust_transition
    initial = np.concatenate([w * m.initial_belief for w, m in zip(weights, models, strict=True)])
    return TypeLiftedModel(
        trust_levels=tuple(first.trust_levels) * k,
        incident_types=tuple(first.incident_types),
        takeover_probability=takeover,
        failure_probability=failure,
        trust_transition=transition,
        initial_belief=initial,
        trust_free_takeover_probability=dict(first.trust_free_takeover_probability),
        source_path=population.source_path,
        provenance=f"type-aware model of the driver population {population.source_path}",
        type_names=population.names,
        n_base_trust=n,
        type_initial=tuple(tuple(float(b) for b in m.initial_belief) for m in models),
        type_prior=tuple(float(w) for w in weights),
        population_hash=population.content_hash,
    )


def type_belief(model: DriverModel, beliefs: np.ndarray) -> np.ndarray:
    """P(type) [..., K] of (lifted) beliefs [..., K·n] (one type: a column of ones' sums)."""
    beliefs = np.asarray(beliefs, dtype=float)
    k = n_types_of(model)
    return beliefs.reshape(*beliefs.shape[:-1], k, beliefs.shape[-1] // k).sum(axis=-1)


def trust_marginal(model: DriverModel, beliefs: np.ndarray) -> np.ndarray:
    """P(trust) [..., n] of (lifted) beliefs [..., K·n]; the beliefs themselves for one type."""
    beliefs = np.asarray(beliefs, dtype=float)
    if not isinstance(model, TypeLiftedModel):
        return beliefs
    k = model.n_types
    return beliefs.reshape(*beliefs.shape[:-1], k, beliefs.shape[-1] // k).sum(axis=-2)


def true_type_initial(model: DriverModel, population: DriverPopulation, type_index: int) -> np.ndarray:
    """The law of the hidden (type, trust) at the start when the driver is of type `type_index`:
    e_k ⊗ b0_k in the lifted index."""
    n = population.types[0].model.n_trust
    out = np.zeros(n_types_of(model) * n)
    out[type_index * n:(type_index + 1) * n] = population.types[type_index].model.initial_belief
    return out


def lift_spec(spec: Spec, population: DriverPopulation, population_source: str = "") -> Spec:
    """`spec` over the lifted model of `population`: belief atoms' coefficients tiled over the
    types, type-belief atoms as belief atoms on their types' blocks; trust-state atoms unchanged
    (they read the trust level of the hidden (type, trust) index, `base_trust_index`). The spec
    itself when the population has one type and the spec no type-belief atoms. A type the
    population does not have: InputError naming both files."""
    source = population_source or population.source_path or "the driver population"
    for name, atom in sorted(spec.type_atoms.items()):
        for type_name in atom.types:
            if type_name not in population.names:
                raise InputError(spec.source_path or spec.name, f"type_beliefs.{name}",
                                 f"type '{type_name}' is not a type of the driver population "
                                 f"{source} (its types: {', '.join(population.names)})",
                                 "name types of that population, or pass the population the spec "
                                 "is written for (--population)")
    if population.n_types == 1 and not spec.type_atoms:
        return spec
    k = population.n_types
    n = population.types[0].model.n_trust
    belief_atoms = {name: BeliefAtom(tuple(atom.coeffs) * k, atom.offset)
                    for name, atom in spec.belief_atoms.items()}
    for name, atom in spec.type_atoms.items():
        coeffs = np.zeros(k * n)
        for type_name in atom.types:
            j = population.type_index(type_name)
            coeffs[j * n:(j + 1) * n] = 1.0
        belief_atoms[name] = BeliefAtom(tuple(float(c) for c in coeffs), atom.above)
    return Spec(name=spec.name, start=spec.start, formula_text=spec.formula_text, formula=spec.formula,
                state_atoms=dict(spec.state_atoms), belief_atoms=belief_atoms,
                source_path=spec.source_path, trust_atoms=dict(spec.trust_atoms))
