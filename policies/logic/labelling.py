"""The labelling function L(x, b) of the trust POMDP feeding a spec's DFA, vectorised.

State atoms are read from a membership table [n_state_atoms, n_roads]; belief atoms are
`offset - coeffs·b < 0`, i.e. `beliefs @ coeffs > offset` (strict; docs/model.md, "scLDTL";
thresholds: docs/synthesis.md, "Labels at thresholds").
Trust-state atoms (docs/trust_states.md) read the hidden trust as well: they are true iff the
road is one of theirs and the trust level index is one of theirs, so they need `trust` (int [n],
trust level indices 0..6) beside the belief. Columns follow `dfa.atoms`.

Rounding margin. A belief b̂ is the float result of the one filter (TrustPOMDP.belief_update): an
n-term product b·W (n multiplications, n - 1 additions of nonnegative terms: relative error θ_n),
its row sum (θ_{n-1} more on top of θ_n) and a division (θ_1). By Higham's lemma 3.3 every
component of b̂ is the exact one-step image of the same previous belief times (1 + θ_{3n}). The
label then takes c·b̂ (forward error γ_n Σ|c_i b̂_i|). So whenever

    |c·b̂ - offset| > γ_{4n+2} · Σ_i |c_i| b̂_i          (γ_k = k u / (1 - k u), u = 2**-53)

every implementation of that filter step and of that dot product, in any summation order (batch
or single row, einsum or BLAS), and exact arithmetic on the same previous belief, read the same
label. `belief_margins` marks beliefs inside that margin (the spec linter's `threshold-hit`).
Synthesis, evaluation and the vehicle read labels on the exact filter's belief along the whole
history instead, deciding them exactly where floats cannot (policies/belief/exact_labels.py).

This machine's strict reading inside the margin is made the same for every caller: c·b is summed
in trust-level order, elementwise over the batch (`atom_values`). A BLAS product `beliefs @ coeffs`
may sum a row in another order depending on how many rows are in the batch, so the search (which
labels its children in batches) and `evaluate` read a belief that sits exactly on a threshold
differently, and the strict-label value the search reports was not the one `evaluate` measured.
"""

from __future__ import annotations

import numpy as np

from trustroute.core.errors import InputError
from trustroute.networks.town import Town
from trustroute.policies.logic.dfa import DFA
from trustroute.policies.logic.road_selectors import unknown_spec_road_fix
from trustroute.policies.logic.spec import N_TRUST_LEVELS, Spec, check_coefficient_length

UNIT_ROUNDOFF = 2.0 ** -53
SMALL_BATCH = 64   # rows: up to here one accumulate beats the loop's two calls per trust level


def gamma(k: int) -> float:
    """Higham's γ_k = k u / (1 - k u): the bound on |θ_k| for k roundings in float64."""
    return k * UNIT_ROUNDOFF / (1.0 - k * UNIT_ROUNDOFF)


def atom_values(beliefs: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """[n, m]: c_j·b for beliefs [n, n_trust] and coeffs [n_trust, m], summed in trust-level
    order for every row whatever the batch size (module docstring), so a label read at a belief is
    the same bit for bit in a batch of any shape."""
    if beliefs.shape[0] <= SMALL_BATCH and coeffs.shape[0]:
        # the same products, added along the trust levels one after another (an accumulate is
        # sequential, unlike a reduction): the loop's sums bit for bit, in two calls
        sums = np.add.accumulate(beliefs[:, :, None] * coeffs[None, :, :], axis=1)
        return np.ascontiguousarray(sums[:, -1, :])
    value = beliefs[:, :1] * coeffs[:1, :]
    for level in range(1, coeffs.shape[0]):
        value = value + beliefs[:, level:level + 1] * coeffs[level:level + 1, :]
    return value


def label_margin_factor(n_trust: int) -> float:
    """γ_{4n+2}: filter step (3n roundings) plus dot product (n) plus two for the margin itself."""
    return gamma(4 * n_trust + 2)


class Labeller:
    """L(x, b) for many positions at once, and the DFA step it drives."""

    def __init__(self, spec: Spec, dfa: DFA, town: Town) -> None:
        self.spec = spec
        self.dfa = dfa
        self.town = town
        road_index = {road: i for i, road in enumerate(town.states)}
        state_columns, belief_columns, trust_columns = [], [], []
        trust_roads, trust_levels = [], []
        membership, offsets = [], []
        coeffs: list[tuple[float, ...]] = []
        for column, atom in enumerate(dfa.atoms):
            if atom in spec.state_atoms:
                row = np.zeros(len(town.states), dtype=bool)
                for road in spec.state_atoms[atom]:
                    if road not in road_index:
                        raise InputError(spec.source_path or spec.name, f"states.{atom}",
                                         f"'{road}' is not a directed road of the town",
                                         unknown_spec_road_fix(town, road))
                    row[road_index[road]] = True
                state_columns.append(column)
                membership.append(row)
            elif atom in spec.belief_atoms:
                belief_columns.append(column)
                if coeffs and len(spec.belief_atoms[atom].coeffs) != len(coeffs[0]):
                    raise InputError(spec.source_path or spec.name, f"beliefs.{atom}.coeffs",
                                     f"belief atom '{atom}' has {len(spec.belief_atoms[atom].coeffs)} "
                                     f"coefficients, another atom has {len(coeffs[0])}",
                                     "give every belief atom one coefficient per trust level")
                coeffs.append(spec.belief_atoms[atom].coeffs)
                offsets.append(spec.belief_atoms[atom].offset)
            elif atom in spec.trust_atoms:
                trust_columns.append(column)
                definition = spec.trust_atoms[atom]
                roads = sorted(definition.roads) if definition.roads is not None else town.states
                for road in roads:
                    if road not in road_index:
                        raise InputError(spec.source_path or spec.name, f"trust_states.{atom}",
                                         f"'{road}' is not a directed road of the town",
                                         unknown_spec_road_fix(town, road))
                trust_roads.append(np.isin(np.arange(len(town.states)),
                                           [road_index[r] for r in roads]))
                trust_levels.append([level in definition.trust for level in range(1, N_TRUST_LEVELS + 1)])
            elif atom in spec.type_atoms:
                raise InputError(spec.source_path or spec.name, f"type_beliefs.{atom}",
                                 f"type-belief atom '{atom}' needs a driver population of types",
                                 "pass --population FILE (docs/driver_types.md)")
            else:
                raise ValueError(f"DFA atom {atom!r} is not defined in spec {spec.name!r}")
        self.state_columns = np.array(state_columns, dtype=np.int64)
        self.belief_columns = np.array(belief_columns, dtype=np.int64)
        self.membership = (np.array(membership, dtype=bool) if membership
                           else np.zeros((0, len(town.states)), dtype=bool))
        self.coeffs = (np.array(coeffs, dtype=float).T if coeffs
                       else np.zeros((0, 0), dtype=float))   # [n_trust, n_belief_atoms]
        self.offsets = np.array(offsets, dtype=float)
        self.trust_columns = np.array(trust_columns, dtype=np.int64)
        self.trust_roads = (np.array(trust_roads, dtype=bool) if trust_roads
                            else np.zeros((0, len(town.states)), dtype=bool))   # [n_trust_atoms, n_x]
        self.trust_levels = (np.array(trust_levels, dtype=bool) if trust_levels
                             else np.zeros((0, N_TRUST_LEVELS), dtype=bool))   # [n_trust_atoms, n_trust]
        # The exact decimals of the coefficients and offsets with their float gaps, built by
        # policies/belief/exact_labels.py on first use and held here: every episode's exact labels
        # of this labeller share them.
        self.exact_constants: tuple | None = None

    def _check_width(self, beliefs: np.ndarray) -> None:
        if self.belief_columns.size and beliefs.shape[-1] != self.coeffs.shape[0]:
            check_coefficient_length(self.spec, int(beliefs.shape[-1]))

    @property
    def reads_trust(self) -> bool:
        """True iff some atom of the DFA is a trust-state atom (then `trust` must be given)."""
        return bool(self.trust_columns.size)

    def valuations(self, x: np.ndarray, beliefs: np.ndarray, trust: np.ndarray | None = None,
                   belief_truth: np.ndarray | None = None) -> np.ndarray:
        """bool [n, len(dfa.atoms)]: the atoms at positions (x[i], beliefs[i], trust[i]).

        belief_truth: the belief atoms' values already decided (bool [n, n_belief_atoms] in
        `belief_columns` order; policies/belief/exact_labels.py decides them exactly)."""
        x = np.asarray(x, dtype=np.int64)
        out = np.empty((x.shape[0], len(self.dfa.atoms)), dtype=bool)
        if self.state_columns.size:
            out[:, self.state_columns] = self.membership[:, x].T
        if self.belief_columns.size and belief_truth is not None:
            out[:, self.belief_columns] = belief_truth
        elif self.belief_columns.size:
            beliefs = np.asarray(beliefs)
            self._check_width(beliefs)
            out[:, self.belief_columns] = atom_values(np.atleast_2d(beliefs), self.coeffs) > self.offsets
        if self.trust_columns.size:
            if trust is None:
                raise ValueError(f"spec {self.spec.name!r} has trust-state atoms: the trust level "
                                 "of each position is needed (docs/trust_states.md)")
            trust = np.asarray(trust, dtype=np.int64)
            out[:, self.trust_columns] = (self.trust_roads[:, x] & self.trust_levels[:, trust]).T
        return out

    def step(self, q: np.ndarray, x: np.ndarray, beliefs: np.ndarray,
             trust: np.ndarray | None = None, belief_truth: np.ndarray | None = None) -> np.ndarray:
        """int [n]: DFA states after reading positions (x, beliefs, trust) from states q
        (belief_truth: as in `valuations`)."""
        return self.dfa.step_many(q, self.valuations(x, beliefs, trust, belief_truth))

    def belief_margins(self, beliefs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(truth, either), bool [n, n_belief_atoms] in `belief_columns` order.

        truth: the strict label `c·b > offset` as `valuations` reads it; either: the belief lies
        within the rounding margin of the atom's hyperplane (module docstring), where another
        implementation of the same filter step could read the other value.
        """
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        if not self.belief_columns.size:
            empty = np.zeros((beliefs.shape[0], 0), dtype=bool)
            return empty, empty
        self._check_width(beliefs)
        value = atom_values(beliefs, self.coeffs)
        margin = label_margin_factor(beliefs.shape[1]) * (np.abs(beliefs) @ np.abs(self.coeffs))
        return value > self.offsets, np.abs(value - self.offsets) <= margin
