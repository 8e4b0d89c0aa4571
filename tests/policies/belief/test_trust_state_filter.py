"""The joint (θ, q) filter: today's filter bit for bit without trust atoms; a law over (θ, q) with them."""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.policies.belief.exact_labels import symbol_code
from trustroute.policies.belief.trust_state_filter import joint_filter
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec


def run(pomdp, spec, route, takeovers):
    town = pomdp.town
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    filter_ = joint_filter(pomdp, dfa, labeller)
    start = town.state_index(route[0])
    belief = np.asarray(pomdp.initial_belief, dtype=float)[None]
    joint = filter_.initial(start, belief[0])
    q = labeller.step(np.array([dfa.initial]), np.array([start]), belief,
                      np.array([0]) if labeller.reads_trust else None)
    history = [(joint, belief, q)]
    labels, word = filter_.labels(), np.zeros(1, dtype=np.int64)
    words = [word]
    for road, h in zip(route[1:], takeovers, strict=True):
        x = np.array([town.state_index(road)])
        incident = pomdp.road_incident[x]
        posterior, p = pomdp.belief_update(belief, incident, h, 0)
        word = labels.filter.extend(word, symbol_code(incident, h, 0))
        joint = filter_.update(joint, posterior, posterior, x, (incident, h, 0), p, word, labels)
        belief = posterior
        if not labeller.reads_trust:
            q = labeller.step(q, x, belief)
        history.append((joint, belief, q))
        words.append(word)
    return filter_, history, words


ROUTE = ["E-A", "A-B", "B-G", "G-I", "I-J", "J-K", "K-L", "L-H"]


def takeovers(town):
    """A takeover on every other road with an incident (none has no takeovers)."""
    incidents = [town.incident(road) != "none" for road in ROUTE[1:]]
    return [int(has and i % 2 == 0) for i, has in enumerate(incidents)]


def test_without_trust_atoms_the_joint_is_todays_belief_times_the_dfa_state(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    _, history, _ = run(pomdp, spec, ROUTE, takeovers(pomdp.town))
    for joint, belief, q in history:
        assert np.array_equal(joint[0, :, int(q[0])], belief[0])       # bit for bit
        assert np.count_nonzero(joint.sum(axis=1)) == 1


def test_with_trust_atoms_the_joint_is_a_law_whose_marginal_is_the_belief(pomdp):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    filter_, history, words = run(pomdp, spec, ROUTE, takeovers(pomdp.town))
    for joint, belief, _ in history:
        assert joint.dtype == np.float64 and abs(joint.sum() - 1.0) < 1e-12
        assert np.allclose(joint.sum(axis=2), belief, atol=1e-12)
    accepted, _, live = filter_.masses(history[-2][0])     # at K-L (v3), after v1 and v2
    # Accepted exactly when the trust at v3 is 6 or 7: the belief's mass there.
    assert abs(accepted[0] - history[-2][1][0, 5:].sum()) < 1e-12
    assert 0 < accepted[0] < 1 and abs(accepted[0] + live[0] - 1) < 1e-12
    # Accepting is absorbing, so P(accepted) is a martingale: averaged over the next observation
    # it stays, although each observation moves it.
    joint, belief, _ = history[-2]
    x = np.array([pomdp.town.state_index("L-H")])   # a truck: takeovers are possible
    incident = pomdp.road_incident[x]
    total, moved = 0.0, []
    labels = filter_.labels()
    for h in (0, 1):
        posterior, p = pomdp.belief_update(belief, incident, h, 0)
        word = labels.filter.extend(words[-2], symbol_code(incident, h, 0))
        after = filter_.masses(filter_.update(joint, posterior, posterior, x, (incident, h, 0), p,
                                              word, labels))[0][0]
        total += float(p[0]) * after
        moved.append(after)
    assert abs(total - accepted[0]) < 1e-12 and min(abs(m - accepted[0]) for m in moved) > 1e-3


def _grouping_by_bytes(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each row, the index of the first row with the same bits; and each row's bytes."""
    first_of: dict[bytes, int] = {}
    firsts = np.array([first_of.setdefault(row.tobytes(), i) for i, row in enumerate(rows)])
    return firsts, np.array([row.tobytes() for row in rows], dtype=object)


@pytest.mark.parametrize("collide", [False, True], ids=["hashed", "every_hash_equal"])
def test_distinct_rows_over_column_blocks_and_row_chunks_groups_rows_by_their_bits(monkeypatch, collide):
    """Rows split into column blocks and hashed a few rows at a time are grouped exactly as their
    bits are (checked against a dictionary of each row's bytes), -0.0 apart from 0.0; the grouping
    and its numbering equal those of the whole matrix in one block. With every hash equal (all
    multipliers zero), the bytes are sorted instead and the grouping is still exact."""
    import trustroute.policies.belief.trust_state_filter as module

    monkeypatch.setattr(module, "HASH_CHUNK", 7)
    if collide:
        monkeypatch.setattr(module, "_hash_multipliers", lambda width: np.zeros(width, dtype=np.uint64))
    rng = np.random.default_rng(3)
    pool = rng.random((12, 9))
    pool[3, 4] = -0.0      # the same number as 0.0 below, other bits: another row
    pool[5] = pool[3]
    pool[5, 4] = 0.0
    rows = pool[rng.integers(0, len(pool), size=200)]
    first, inverse = module.distinct_rows(rows[:, :1], rows[:, 1:5], rows[:, 5:])
    whole = module.distinct_rows(rows)
    assert np.array_equal(first, whole[0]) and np.array_equal(inverse, whole[1])
    firsts, keys = _grouping_by_bytes(rows)
    assert np.array_equal(first[inverse], firsts)          # each row's group starts at its first copy
    assert len(set(keys[first])) == first.size             # and no two groups hold the same bits
