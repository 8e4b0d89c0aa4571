"""The product of the trust belief MDP with a spec's DFA, as lookup tables.

A product state is (x, q, b): directed road x, DFA state q after reading position (x, b), AV
belief b. Choosing the next junction moves to road x'; the symbol o seen on x' updates the belief
to b' = f_o(b) and the DFA reads position (x', b'): q' = δ(q, L(x', b')). Positions and labels
follow docs/model.md, "Positions of a trace" and "The product"; the DFA is the scLDTL helper's
(policies/logic/dfa.py).

`next_q[q, x', bits]` tabulates δ for every road and every valuation of the belief atoms
(bit j of `bits` = value of `belief_atoms[j]`), so abstract solvers can branch on label
values without touching beliefs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.core.errors import InputError
from trustroute.policies.belief.exact_labels import exact_labels
from trustroute.policies.belief.problem import dfa_is_hidden
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.dfa import DFA
from trustroute.policies.logic.labelling import Labeller, check_coefficient_length
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP


@dataclass(frozen=True, eq=False)
class ProductTables:
    pomdp: TrustPOMDP
    spec: Spec
    dfa: DFA
    labeller: Labeller
    start: int                      # road index of position 0
    initial_q: int                  # DFA state after reading position 0 with the initial belief
    #                                 (its labels decided exactly: policies/belief/exact_labels.py)
    accepting: np.ndarray           # bool [n_q]
    rejecting: np.ndarray           # bool [n_q] (and not accepting)
    successors: np.ndarray          # [n_x, n_actions] road index or -1
    belief_atom_names: tuple[str, ...]
    belief_coeffs: np.ndarray       # [n_atoms, n_trust]
    belief_offsets: np.ndarray      # [n_atoms]
    next_q: np.ndarray              # [n_q, n_x, 2**n_atoms]

    @property
    def n_q(self) -> int:
        return int(self.dfa.n_states)

    @property
    def n_x(self) -> int:
        return int(self.successors.shape[0])

    def step(self, q: np.ndarray, x: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        """Exact DFA step on positions (x, b), through the spec helper's labeller."""
        if q.size == 0:
            return np.zeros(0, dtype=np.int64)
        return np.asarray(self.labeller.step(q, x, beliefs), dtype=np.int64)


def build_product(pomdp: TrustPOMDP, spec: Spec) -> ProductTables:
    if dfa_is_hidden(pomdp.driver, spec):
        raise InputError(spec.source_path or spec.name, "formula",
                         "the belief-MDP product cannot test the hidden trust (trust-state atoms)",
                         "evaluate with policies.evaluation.trust_state or bound with "
                         "policies.trust_state_synthesis.search (docs/trust_states.md)")
    town = pomdp.town
    check_coefficient_length(spec, pomdp.n_trust, pomdp.driver.source_path)
    compiled = compile_spec(spec, town)
    dfa, labeller = compiled.dfa, compiled.labeller
    belief_names, next_q = compiled.label_table()
    m = len(belief_names)
    coeffs = np.array([spec.belief_atoms[a].coeffs for a in belief_names], dtype=float).reshape(
        m, pomdp.n_trust)
    offsets = np.array([spec.belief_atoms[a].offset for a in belief_names], dtype=float)
    start = town.state_index(spec.start)
    initial_q = int(exact_labels(pomdp, labeller).step(
        np.array([dfa.initial]), np.array([start]), np.asarray(pomdp.initial_belief, dtype=float)[None, :],
        np.zeros(1, dtype=np.int64))[0])
    accepting = np.asarray(dfa.accepting, dtype=bool)
    rejecting = np.asarray(dfa.rejecting, dtype=bool) & ~accepting
    return ProductTables(pomdp=pomdp, spec=spec, dfa=dfa, labeller=labeller, start=start,
                         initial_q=initial_q, accepting=accepting, rejecting=rejecting,
                         successors=np.asarray(pomdp.successor_table, dtype=np.int64),
                         belief_atom_names=belief_names, belief_coeffs=coeffs,
                         belief_offsets=offsets, next_q=next_q)
