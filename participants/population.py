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
from typing import TypedDict

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.fields import PROBABILITY, Field, ListOf, Number, check_fields, field_table
from trustroute.core.wording import shown_value
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
# Every key of the table (docs/formats/study_config.md, "`[population]`"); the rules below check what
# a table cannot (one entry per trust level, summing to 1).

class PopulationTableValues(TypedDict):
    """The checked values of a [population] table."""

    concentration: float
    takeover_spread: float
    initial_trust: list[float] | None
    report_accuracy: float


FIELDS = field_table(
    PopulationTableValues,
    Field(key="concentration", kind=Number(minimum=0.0, open_below=True, finite=False), default=math.inf,
          problem=lambda seen: f"{shown_value(seen.value)} is not a number > 0",
          fix="give a positive concentration, or inf for the nominal model"),
    Field(key="takeover_spread", kind=Number(minimum=0.0), default=0.0,
          problem=lambda seen: f"{shown_value(seen.value)} is not a finite number >= 0",
          fix="give the sd of the logit shift, 0 for none"),
    Field(key="initial_trust", kind=ListOf(item=PROBABILITY, min_items=1),
          problem=lambda seen: f"{shown_value(seen.value, 60)} is not a list of probabilities",
          fix="give one probability per trust level"),
    Field(key="report_accuracy", kind=PROBABILITY, default=DEFAULT_REPORT_ACCURACY,
          problem=lambda seen: f"{shown_value(seen.value)} is not a probability",
          fix="give a number in [0, 1]"),
)


def _initial_trust(dist: list | None, source: str, n_trust: int | None) -> tuple[float, ...] | None:
    """One probability per trust level (when `n_trust` is known), summing to 1."""
    if dist is None:
        return None
    if n_trust is not None and len(dist) != n_trust:
        raise InputError(source, "population.initial_trust", f"has {len(dist)} entries, the "
                         f"driver model has {n_trust} trust levels", "give one per trust level")
    total = math.fsum(dist)
    if abs(total - 1) > ROW_TOLERANCE:
        raise InputError(source, "population.initial_trust", f"sums to {total:.12g}, not 1",
                         "renormalise it")
    return tuple(float(v) for v in dist)


def _checked(data: object, source: str) -> PopulationTableValues:
    if not isinstance(data, Mapping):
        raise InputError(source, "population", "expected a table", "write a [population] table")
    return check_fields(dict(data), FIELDS, source, "[population] table", "population")


def population_table(data: Mapping[str, object], source: str) -> dict[str, object]:
    """The keys a `[population]` table gives, each value as checked (a numpy number as Python's),
    the table a study config keeps and writes; InputError as `population_config_from_dict`."""
    population_config_from_dict(data, source)
    values = _checked(data, source)
    return {key: values[key] for key in data}   # type: ignore[literal-required]


def population_config_from_dict(data: Mapping[str, object] | None, source: str,
                                n_trust: int | None = None) -> PopulationConfig:
    """Validate a `[population]` table (parsed TOML) into a PopulationConfig, or raise InputError.

    Missing keys take the defaults (nominal drivers). `concentration` may be TOML `inf`.
    Give `n_trust` to check the length of `initial_trust` against the driver model.
    """
    if data is None:
        return PopulationConfig()
    values = _checked(data, source)
    initial_trust = _initial_trust(values["initial_trust"], source, n_trust)
    return PopulationConfig(concentration=float(values["concentration"]),
                            takeover_spread=float(values["takeover_spread"]),
                            initial_trust=initial_trust, report_accuracy=float(values["report_accuracy"]))
