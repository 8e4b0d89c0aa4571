"""The memory of an exact evaluation follows its frontier, not every history it has seen.

An unfolding keeps one level of histories at a time: the routes and the words of its exact belief
labels (policies/belief/exact_labels.py) are its own, forgotten level by level once no open history
holds them; a level's children are written into one set of arrays, its decisions grouped in arrays,
and its belief updates and label steps run in blocks of rows. A 40-junction evaluation under a
node budget holds under 2 kB per budgeted history, however many histories it has seen, and still
gives the exact values of the plain recursion. A level whose children would not fit in the memory
available is refused before it is allocated."""

from __future__ import annotations

import tracemalloc
from dataclasses import replace

import numpy as np
import numpy.ma  # noqa: F401  (numpy loads it on first use, inside the evaluation: not its memory)
import pytest

import trustroute
from tests.cli import run_cli
from tests.policies.evaluation.test_plain import RANDOM_POLICY_SEED, RandomStationaryPolicy, recursive_value
from trustroute.core.errors import InputError
from trustroute.policies.belief import exact_labels
from trustroute.policies.evaluation import unfolding
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model import trust_pomdp
from trustroute.policies.routing.fallback import with_fallback

BUDGET = 1_000        # histories per junction
JUNCTIONS = 40        # the budget is reached by junction 16: 24 levels at the budget
# Bytes per budgeted history at the evaluation's peak, measured 1,650 (phi1) and 1,520 (phi2): a
# level holds its nodes' arrays (104 bytes: road, probability, route, DFA states, word: 8 each;
# the AV's belief, which is the true posterior here, 7 x 8), its children in one set of arrays (up
# to 2 per node), the words of its exact labels (24 bytes each in arrays, about 4 per history with
# their prefixes, and a lookup entry per word the level makes; the largest part while they grow or
# are compacted) and the unfolding's fixed costs spread over the budget. Each of these comes on
# top: every observation's children and their joined copy at once, a Python key per decision, the
# nodes moved held through the trim, the routes of every history seen (about 224 bytes each), a
# belief update's [rows, 7, 7] matrices for all of a level's rows at once: 2,640 (phi1) and 2,320
# (phi2) bytes with all of them.
BYTES_PER_HISTORY = 1_800
# The unbounded phi1 policy (the result digest's work limit), 60 junctions, no fallback, as in the
# runs docs/model.md measures in resident memory, at half their smallest budget: the run's fixed
# costs weigh more on a smaller budget (5.3 copies at 20,000, 5.6 at 10,000, 6.7 at 5,000), so the
# bound is held where it is tighter, in half the time; a PEAK_COPIES of 5 or less fails here.
PEAK_BUDGET = 10_000
# Belief updates and label steps run trust_pomdp.BLOCK_ROWS rows at a time; blocks of 256 rows are
# small beside a level of up to 2,000 children, as 4,096 rows are beside the levels of the default
# budget (2,000,000).
TEST_BLOCK_ROWS = 256


def random_policy(pomdp, name):
    return RandomStationaryPolicy(pomdp.town, np.random.default_rng(RANDOM_POLICY_SEED[name]))


def traced_peak(run):
    """(run's result, the peak of memory it allocated, from tracemalloc)."""
    tracemalloc.start()
    try:
        result = run()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("name", ["phi1", "phi2"])
def test_memory_per_budgeted_history_is_bounded_over_many_junctions(pomdp, name, monkeypatch):
    monkeypatch.setattr(trust_pomdp, "BLOCK_ROWS", TEST_BLOCK_ROWS)
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    policy = random_policy(pomdp, name)
    settings = EvaluationSettings(fallback_after=None, max_junctions=JUNCTIONS, max_nodes=BUDGET)
    # the same paths on a tenth of the budget first: what is loaded or cached once is not counted
    evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=JUNCTIONS,
                                                     max_nodes=BUDGET // 10))
    evaluation, peak = traced_peak(lambda: evaluate(pomdp, spec, policy, settings))
    assert evaluation.max_frontier == BUDGET and evaluation.nodes > 25 * BUDGET
    assert peak < BYTES_PER_HISTORY * BUDGET, f"{peak / BUDGET:.0f} bytes per history"


def test_the_routes_kept_are_those_of_the_open_histories(pomdp, monkeypatch):
    """Every route a level's histories are on is new, so the unfolding holds the routes of the
    histories its last level kept alone (at most its budget), not every route it has seen."""
    budget = BUDGET // 10
    held = []
    act = unfolding.EpisodeActor.act

    def spied(actor, level, frontier):
        held.append((len(actor.routes), int(frontier.route_id.max())))
        return act(actor, level, frontier)

    monkeypatch.setattr(unfolding.EpisodeActor, "act", spied)
    evaluate(pomdp, load_spec("specs/phi1.toml", pomdp.town), random_policy(pomdp, "phi1"),
             EvaluationSettings(fallback_after=None, max_junctions=JUNCTIONS, max_nodes=budget))
    assert len(held) == JUNCTIONS + 1 and max(kept for kept, _ in held) > 20
    assert all(last < kept <= budget for kept, last in held)


def test_compacting_routes_keeps_their_order(pomdp):
    town = pomdp.town
    actor = unfolding.EpisodeActor(policy=random_policy(pomdp, "phi1"), town=town, max_junctions=3,
                                   fallback_level=None, accepting=np.zeros(1, dtype=bool),
                                   routes=[(road,) for road in town.states[:4]])
    assert actor.compact(np.array([3, 1, 3])).tolist() == [1, 0, 1]
    assert actor.routes == [(town.states[1],), (town.states[3],)]
    kept = np.array([0, 1])
    assert actor.compact(kept) is kept      # nothing to forget: the ids as they are


@pytest.mark.parametrize("name", ["phi1", "phi2"])
@pytest.mark.parametrize("belief_rule", ["bayes", "paper"])
def test_compacted_words_give_the_exact_values_of_the_recursion(pomdp, name, belief_rule, monkeypatch):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    policy = with_fallback(random_policy(pomdp, name), pomdp.town, spec, after=6)
    settings = EvaluationSettings(max_junctions=13, belief_rule=belief_rule)
    unforced = evaluate(pomdp, spec, policy, settings).to_dict()
    monkeypatch.setattr(exact_labels, "COMPACT_AT_LEAST", 0)    # renumber at every doubling
    compacted = evaluate(pomdp, spec, policy, settings)
    satisfied, final_trust = recursive_value(pomdp, spec, policy, 13, belief_rule)
    assert compacted.gap == 0.0
    assert compacted.lower == pytest.approx(satisfied, abs=1e-12)
    assert compacted.expected_final_trust == pytest.approx(final_trust, abs=1e-9)
    assert {**compacted.to_dict(), "seconds": 0} == {**unforced, "seconds": 0}


def test_a_level_that_would_not_fit_is_refused_before_it_is_allocated(pomdp, monkeypatch):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    monkeypatch.setattr(unfolding, "available_memory", lambda: 20_000)
    with pytest.raises(InputError) as refused:
        evaluate(pomdp, spec, random_policy(pomdp, "phi1"), EvaluationSettings(fallback_after=None))
    message = str(refused.value)
    assert "--max-nodes" in message and "GB of memory available" in message
    fits = int(message.split("pass --max-nodes ")[1].split(" ")[0].replace(",", ""))
    assert 1 <= fits < 100


def test_the_command_says_so_in_one_line(capsys, monkeypatch):
    monkeypatch.setattr(unfolding, "available_memory", lambda: 1_000)
    code, out, err = run_cli(capsys, "evaluate", "phi1", "free", "--no-fallback")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "--max-nodes 1 or less" in err and "--max-junctions" in err


@pytest.mark.slow
def test_a_whole_run_needs_at_most_peak_copies_of_its_largest_junction(pomdp, monkeypatch):
    """A refusal's suggested budget is one whole run at that budget: what the run allocates beyond
    what it holds at its first junction stays within PEAK_COPIES copies of its largest junction's
    children as check_memory counts them (histories x observations x bytes per history). Measured
    in allocations here (5.6 copies); in resident memory the run at 20,000 needs 5.7-6.3
    (unfolding.PEAK_COPIES says how)."""
    spec = load_spec("specs/phi1.toml", pomdp.town)
    policy = trustroute.synthesize("specs/phi1.toml", time_limit=600, work_limit=3_000_000).policy
    settings = EvaluationSettings(fallback_after=None, max_junctions=60, max_nodes=PEAK_BUDGET)
    evaluate(pomdp, spec, policy, replace(settings, max_nodes=PEAK_BUDGET // 100))  # caches, imports
    checked, check = [], unfolding.check_memory

    def counted(level, frontier, n_observations):
        children = frontier.size * n_observations * frontier.bytes_per_node
        checked.append((tracemalloc.get_traced_memory()[0], children))
        return check(level, frontier, n_observations)

    monkeypatch.setattr(unfolding, "check_memory", counted)
    evaluation, peak = traced_peak(lambda: evaluate(pomdp, spec, policy, settings))
    needed, largest = peak - checked[0][0], max(children for _, children in checked)
    assert evaluation.max_frontier == PEAK_BUDGET
    assert needed <= unfolding.PEAK_COPIES * largest, f"{needed / largest:.2f} copies"
