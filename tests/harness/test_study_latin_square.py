"""Counterbalancing (Williams design) and the episode plan's seeds."""

from __future__ import annotations

from collections import Counter
from itertools import pairwise
from pathlib import Path

import pytest

from trustroute.harness.study.config import study_config_from_dict
from trustroute.harness.study.latin_square import participant_order, williams_rows
from trustroute.harness.study.plan import plan_episodes

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("n", range(1, 9))
def test_each_condition_once_per_row_and_equally_often_per_position(n):
    rows = williams_rows(n)
    assert len(rows) == (n if n % 2 == 0 or n == 1 else 2 * n)
    for row in rows:
        assert sorted(row) == list(range(n))
    for position in range(n):
        counts = Counter(row[position] for row in rows)
        assert set(counts) == set(range(n))
        assert len(set(counts.values())) == 1


@pytest.mark.parametrize("n", range(2, 9))
def test_first_order_carryover_balanced(n):
    rows = williams_rows(n)
    pairs = Counter(pair for row in rows for pair in pairwise(row))
    expected = {(a, b) for a in range(n) for b in range(n) if a != b}
    assert set(pairs) == expected
    assert len(set(pairs.values())) == 1  # every ordered pair equally often (once / twice)


def test_paper_design_four_conditions_over_participants():
    # 4 conditions (aware/free x phi1/phi2): 20 participants = 5 full squares, exactly balanced
    orders = [participant_order(p, 4) for p in range(20)]
    for position in range(4):
        assert Counter(o[position] for o in orders) == {c: 5 for c in range(4)}
    carry = Counter(pair for o in orders for pair in pairwise(o))
    assert set(carry.values()) == {5} and len(carry) == 12


def _config(participants=8, seed=1):
    data = {
        "study": {
            "participants": participants,
            "seed": seed,
            "engine": "model",
            "specs": ["phi1", "phi2"],
            "conditions": ["aware", "free"],
        }
    }
    return study_config_from_dict(data, "test.toml", REPO)


def test_plan_covers_every_cell_once_per_participant_in_latin_order():
    tasks = plan_episodes(_config(8))
    assert len(tasks) == 32 and len({t.episode_id for t in tasks}) == 32
    for p in range(8):
        mine = sorted((t for t in tasks if t.participant == p), key=lambda t: t.position)
        cells = [t.spec_index * 2 + t.condition_index for t in mine]
        assert tuple(cells) == participant_order(p, 4)


def test_seeds_depend_on_cell_not_on_plan_size_or_order():
    small = {t.episode_id: t for t in plan_episodes(_config(3))}
    large = {t.episode_id: t for t in plan_episodes(_config(30))}
    for key, task in small.items():
        assert large[key].seed == task.seed and large[key].driver_entropy == task.driver_entropy
        assert (task.driver_rng().random(3) == large[key].driver_rng().random(3)).all()
    seeds = [t.seed for t in large.values()]
    assert len(set(seeds)) == len(seeds)
    assert all(0 <= s < 2**31 for s in seeds)
    other = {t.episode_id: t.seed for t in plan_episodes(_config(3, seed=2))}
    assert all(other[k] != small[k].seed for k in small)
