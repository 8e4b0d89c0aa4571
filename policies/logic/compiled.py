"""A spec compiled against a town: its DFA, the labeller feeding it, the initial state and the step.

`compile_spec(spec, town)` is the one place the DFA-plus-labeller pair is built. Episodes, the exact
evaluation, synthesis, POUCT, trace evaluation, the linter and the state-only task all read a spec
through it. Position 0 of a trace is the spec's start road: q_0 = step(dfa.initial, start, b_0).
The spec holds its compilations (Spec.compilations, by the town's content hash), so everything
reading one loaded spec shares one DFA and its arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from trustroute.core.errors import InputError
from trustroute.core.wording import shown_value
from trustroute.networks.town import Town
from trustroute.policies.logic.dfa import DFA, build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.road_selectors import unknown_spec_road_fix
from trustroute.policies.logic.spec import Spec


@dataclass(frozen=True, eq=False)
class CompiledSpec:
    """The DFA of `spec`, the labeller L(x, b) on `town`, and the DFA step on positions (x, b)."""

    spec: Spec
    town: Town
    dfa: DFA
    labeller: Labeller
    accepting: np.ndarray   # bool [n_states]
    rejecting: np.ndarray   # bool [n_states]: can no longer accept
    start: int              # index of the spec's start road in town.states
    _label_table: tuple | None = field(default=None, repr=False)
    # What other modules derive from this compiled spec, built once and held with it (name ->
    # object): policies/routing/free.py's state-only task and trust-free completion.
    derived: dict = field(default_factory=dict, repr=False)

    def step(self, q: np.ndarray, x: np.ndarray, beliefs: np.ndarray) -> np.ndarray:
        """int64 [n]: DFA states after reading positions (x[i], beliefs[i]) from states q[i]."""
        if np.size(q) == 0:
            return np.zeros(0, dtype=np.int64)
        return np.asarray(self.labeller.step(q, x, beliefs), dtype=np.int64)

    def initial_states(self, beliefs: np.ndarray) -> np.ndarray:
        """int64 [n]: q_0 of n episodes whose initial beliefs are the rows of `beliefs`."""
        beliefs = np.atleast_2d(np.asarray(beliefs, dtype=float))
        n = beliefs.shape[0]
        return self.step(np.full(n, self.dfa.initial, dtype=np.int64), np.full(n, self.start), beliefs)

    def initial_state(self, belief: np.ndarray) -> int:
        """q_0 of one episode with initial belief `belief`."""
        return int(self.initial_states(np.asarray(belief, dtype=float)[None, :])[0])

    def step_road(self, q: int, road: str, belief: np.ndarray) -> int:
        """The DFA state after reading one position (road, belief) from state q."""
        x = self.town.state_index(road)
        return int(self.step(np.array([q]), np.array([x]), np.asarray(belief, dtype=float)[None, :])[0])

    def label_table(self) -> tuple[tuple[str, ...], np.ndarray]:
        """(belief atom names, next_q [n_q, n_x, 2**m]): the DFA step on every road for every
        valuation of the m belief atoms of the DFA (bit j of the last index = belief_atoms[j]);
        state atoms read from the road. Computed once per compiled spec."""
        cached = self._label_table
        if cached is None:
            dfa, spec, town = self.dfa, self.spec, self.town
            atoms = tuple(dfa.atoms)
            names = tuple(a for a in atoms if a in spec.belief_atoms)
            n_x, n_q, m = len(town.states), int(dfa.n_states), len(names)
            q_grid, x_grid, bits_grid = np.meshgrid(np.arange(n_q), np.arange(n_x), np.arange(2 ** m),
                                                    indexing="ij")
            valuations = np.zeros((q_grid.size, len(atoms)), dtype=bool)
            roads = np.array(town.states)[x_grid.ravel()]
            for j, atom in enumerate(atoms):
                if atom in spec.belief_atoms:
                    valuations[:, j] = (bits_grid.ravel() >> names.index(atom)) & 1
                else:
                    members = spec.state_atoms.get(atom, frozenset())
                    valuations[:, j] = np.isin(roads, list(members))
            next_q = np.asarray(dfa.step_many(q_grid.ravel(), valuations), dtype=np.int64).reshape(
                n_q, n_x, 2 ** m)
            next_q.setflags(write=False)
            cached = (names, next_q)
            object.__setattr__(self, "_label_table", cached)
        return cached


def compile_spec(spec: Spec, town: Town) -> CompiledSpec:
    """`spec` compiled against `town`: built on the first call and held by the spec."""
    compiled = spec.compilations.get(town.content_hash)
    if compiled is None:
        if spec.start not in town.states:
            raise InputError(spec.source_path or spec.name, "start",
                             f"start road {shown_value(spec.start)} is not a directed road of the town",
                             unknown_spec_road_fix(town, spec.start))
        dfa = build_dfa(spec)
        labeller = Labeller(spec, dfa, town)
        compiled = CompiledSpec(spec=spec, town=town, dfa=dfa, labeller=labeller,
                                accepting=np.asarray(dfa.accepting, dtype=bool),
                                rejecting=np.asarray(dfa.rejecting, dtype=bool),
                                start=town.state_index(spec.start))
        spec.compilations[town.content_hash] = compiled
    return compiled
