"""One step of the AV after driving a road, vectorised over rows: its belief filtered on the
observation (TrustPOMDP.filter: an impossible observation keeps the prior), the belief's word
extended by the observation's symbol (kept where the observation was impossible: the belief did
not move), and the spec's DFA stepped on the position (road, new belief), belief labels decided on
the word where floats cannot decide them (exact_labels.py). The batch model engine and the exact
evaluation step through it; the episode tracker steps the same filter one row at a time, memoised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.policies.belief.exact_labels import ExactLabels, symbol_code
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP


@dataclass(frozen=True, eq=False)
class AVStep:
    """The AV's filter (`pomdp` under `rule`) and its belief labels (`labels`, the same rule's)."""

    pomdp: TrustPOMDP
    labels: ExactLabels
    rule: BeliefRule

    def belief_and_word(self, belief: np.ndarray, word: np.ndarray, incident: np.ndarray,
                        human_action: np.ndarray | int, performance: np.ndarray | int
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(posterior, word, possible) per row after the observation (incident, h, e)."""
        posterior, possible = self.pomdp.filter(belief, incident, human_action, performance, rule=self.rule)
        extended = self.labels.filter.extend(word, symbol_code(incident, human_action, performance))
        return posterior, np.where(possible, extended, word), possible

    def step(self, belief: np.ndarray, word: np.ndarray, q: np.ndarray, road: np.ndarray,
             observation: tuple[np.ndarray, np.ndarray | int, np.ndarray | int]
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(posterior, word, DFA state, possible) per row after driving `road` and observing
        `observation` = (incident, h, e), from DFA state `q`."""
        posterior, word, possible = self.belief_and_word(belief, word, *observation)
        q = np.asarray(self.labels.step(q, road, posterior, word), dtype=np.int64)
        return posterior, word, q, possible
