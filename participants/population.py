"""Populations of synthetic drivers: individual driver models sampled around a nominal one.

Owns `PopulationConfig`, its loader from a `[population]` table, and `sample_population`.
Each individual is a full `DriverModel`:
- every trust-transition row is Dirichlet(concentration · nominal row) over the support of
  the nominal row (zeros stay zeros), so its mean is the nominal row and concentration = inf
  gives the nominal row exactly;
- the takeover probabilities get one logit shift per driver, N(0, takeover_spread²)
  (0 and 1 stay fixed: a driver who never / always takes over on an incident stays so);
- the initial trust distribution (config.initial_trust, else the model's) is Dirichlet
  around it in the same way.
The AV's failure model and the trust-free takeover table are properties of the AV and the
baseline, not of the driver, and stay nominal. Every draw goes through the Generator passed in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TypedDict, TypeGuard

import numpy as np

from trustroute.core.errors import InputError
from trustroute.participants.driver_model import DEFAULT_REPORT_ACCURACY, ROW_TOLERANCE, DriverModel


@dataclass(frozen=True)
class PopulationConfig:
    concentration: float = math.inf    # Dirichlet concentration around each nominal row; inf = nominal
    takeover_spread: float = 0.0       # sd of a per-driver logit shift of takeover probabilities
    initial_trust: tuple[float, ...] | None = None   # per-driver initial distribution (None: model's)
    report_accuracy: float = DEFAULT_REPORT_ACCURACY

    def __post_init__(self) -> None:
        if not (self.concentration > 0):   # also rejects NaN
            raise ValueError(f"concentration must be > 0 (inf for the nominal model), "
                             f"got {self.concentration!r}")
        if not (math.isfinite(self.takeover_spread) and self.takeover_spread >= 0):
            raise ValueError(f"takeover_spread must be a finite number >= 0, got {self.takeover_spread!r}")
        if not 0.0 <= self.report_accuracy <= 1.0:
            raise ValueError(f"report_accuracy must lie in [0, 1], got {self.report_accuracy!r}")
        if self.initial_trust is not None:
            values = np.asarray(self.initial_trust, dtype=float)
            if (values.ndim != 1 or not np.all(np.isfinite(values)) or values.min() < 0
                    or abs(values.sum() - 1) > ROW_TOLERANCE):
                raise ValueError(f"initial_trust {self.initial_trust!r} is not a probability vector")
            object.__setattr__(self, "initial_trust", tuple(float(v) for v in values))


def _dirichlet_around(nominal: np.ndarray, concentration: float,
                      rng: np.random.Generator) -> np.ndarray:
    """Dirichlet(concentration · p) on the support of p; exactly p when concentration is inf."""
    if math.isinf(concentration):
        return np.array(nominal, dtype=float)
    out = np.zeros_like(nominal, dtype=float)
    support = np.flatnonzero(nominal > 0)
    if support.size == 1:
        out[support] = 1.0
        return out
    alpha = concentration * nominal[support] / nominal[support].sum()
    sample = rng.dirichlet(alpha)
    total = sample.sum()
    if not (total > 0 and np.all(np.isfinite(sample))):
        # Tiny α can underflow every component to 0; fall back to the nominal row rather than
        # invent a distribution (only happens for absurdly small concentrations).
        return np.array(nominal, dtype=float)
    out[support] = sample / total
    return out


def _shift_logits(probabilities: np.ndarray, shift: float) -> np.ndarray:
    if shift == 0.0:
        return np.array(probabilities, dtype=float)
    inner = (probabilities > 0) & (probabilities < 1)
    out = np.array(probabilities, dtype=float)
    p = probabilities[inner]
    out[inner] = 1.0 / (1.0 + np.exp(-(np.log(p) - np.log1p(-p) + shift)))
    return out


def sample_individual(nominal: DriverModel, config: PopulationConfig, rng: np.random.Generator,
                      label: str = "individual") -> DriverModel:
    """One driver model sampled around `nominal` (see the module docstring)."""
    base_initial = (nominal.initial_belief if config.initial_trust is None
                    else np.asarray(config.initial_trust, dtype=float))
    if base_initial.shape != (nominal.n_trust,):
        raise ValueError(f"initial_trust has {base_initial.size} entries but the driver model has "
                         f"{nominal.n_trust} trust levels")
    shift = float(rng.normal(0.0, config.takeover_spread)) if config.takeover_spread > 0 else 0.0
    takeover = _shift_logits(nominal.takeover_probability, shift)
    nominal_t = nominal.trust_transition
    transition = np.empty_like(nominal_t)
    n_inc, n_h, n_e, n, _ = nominal_t.shape
    for i in range(n_inc):
        for h in range(n_h):
            for e in range(n_e):
                if e > 0 and np.array_equal(nominal_t[i, h, e], nominal_t[i, h, 0]):
                    # a performance-independent model stays performance-independent
                    transition[i, h, e] = transition[i, h, 0]
                    continue
                for theta in range(n):
                    transition[i, h, e, theta] = _dirichlet_around(nominal_t[i, h, e, theta],
                                                                   config.concentration, rng)
    initial = _dirichlet_around(base_initial, config.concentration, rng)
    return DriverModel(
        trust_levels=nominal.trust_levels,
        incident_types=nominal.incident_types,
        takeover_probability=takeover,
        failure_probability=nominal.failure_probability,
        trust_transition=transition,
        initial_belief=initial,
        trust_free_takeover_probability=dict(nominal.trust_free_takeover_probability),
        source_path=f"{nominal.source_path} ({label})",
        provenance=f"sampled around {nominal.source_path}: {config}",
    )


def sample_population(nominal: DriverModel, count: int, config: PopulationConfig,
                      rng: np.random.Generator) -> list[DriverModel]:
    """`count` individual driver models around `nominal`; reproducible from the Generator's seed."""
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    return [sample_individual(nominal, config, rng, label=f"individual {k}") for k in range(count)]


# -- the [population] table of a study file --------------------------------------------------

_KEYS = ("concentration", "takeover_spread", "initial_trust", "report_accuracy")


def _number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, int | float) and not isinstance(value, bool)


class _PopulationValues(TypedDict, total=False):
    """The PopulationConfig fields a [population] table gives."""

    concentration: float
    takeover_spread: float
    report_accuracy: float
    initial_trust: tuple[float, ...]


def population_config_from_dict(data: Mapping[str, object] | None, source: str,
                                n_trust: int | None = None) -> PopulationConfig:
    """Validate a `[population]` table (parsed TOML) into a PopulationConfig, or raise InputError.

    Missing keys take the defaults (nominal drivers). `concentration` may be TOML `inf`.
    Give `n_trust` to check the length of `initial_trust` against the driver model.
    """
    if data is None:
        return PopulationConfig()
    if not isinstance(data, Mapping):
        raise InputError(source, "population", "expected a table", "write a [population] table")
    unknown = sorted(set(data) - set(_KEYS))
    if unknown:
        raise InputError(source, f"population.{unknown[0]}", f"unknown key '{unknown[0]}'",
                         f"use only {', '.join(_KEYS)}")
    values: _PopulationValues = {}
    if "concentration" in data:
        c = data["concentration"]
        if not (_number(c) and c > 0):
            raise InputError(source, "population.concentration", f"{c!r} is not a number > 0",
                             "give a positive concentration, or inf for the nominal model")
        values["concentration"] = float(c)
    if "takeover_spread" in data:
        s = data["takeover_spread"]
        if not (_number(s) and math.isfinite(s) and s >= 0):
            raise InputError(source, "population.takeover_spread", f"{s!r} is not a finite number >= 0",
                             "give the sd of the logit shift, 0 for none")
        values["takeover_spread"] = float(s)
    if "report_accuracy" in data:
        a = data["report_accuracy"]
        if not (_number(a) and 0 <= a <= 1):
            raise InputError(source, "population.report_accuracy", f"{a!r} is not a probability",
                             "give a number in [0, 1]")
        values["report_accuracy"] = float(a)
    if "initial_trust" in data:
        dist = data["initial_trust"]
        if not (isinstance(dist, list) and dist and all(_number(v) and math.isfinite(v) and 0 <= v <= 1
                                                        for v in dist)):
            raise InputError(source, "population.initial_trust", f"{dist!r} is not a list of "
                             "probabilities", "give one probability per trust level")
        if n_trust is not None and len(dist) != n_trust:
            raise InputError(source, "population.initial_trust", f"has {len(dist)} entries, the "
                             f"driver model has {n_trust} trust levels", "give one per trust level")
        total = math.fsum(dist)
        if abs(total - 1) > ROW_TOLERANCE:
            raise InputError(source, "population.initial_trust", f"sums to {total:.12g}, not 1",
                             "renormalise it")
        values["initial_trust"] = tuple(float(v) for v in dist)
    return PopulationConfig(**values)
