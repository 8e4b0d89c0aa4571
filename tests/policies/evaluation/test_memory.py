"""The memory of an exact evaluation follows its frontier, not every history it has seen.

An unfolding keeps one level of histories at a time, and the words of its exact belief labels
(policies/belief/exact_labels.py) are its own, compacted level by level to those the frontier still
holds: a 60-junction evaluation under a node budget holds a few kB per budgeted history, however
many histories it has seen, and still gives the exact values of the plain recursion. A level
whose children would not fit in the memory available is refused before it is allocated."""

from __future__ import annotations

import tracemalloc

import numpy as np
import numpy.ma  # noqa: F401  (numpy loads it on first use, inside the evaluation: not its memory)
import pytest

from tests.cli import run_cli
from tests.policies.evaluation.test_plain import RANDOM_POLICY_SEED, RandomStationaryPolicy, recursive_value
from trustroute.core.errors import InputError
from trustroute.policies.belief import exact_labels
from trustroute.policies.evaluation import unfolding
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.fallback import with_fallback

BUDGET = 300          # histories per junction
JUNCTIONS = 40        # the budget is reached by junction 10: 30 levels at the budget
# Bytes per budgeted history at the evaluation's peak: a node's arrays are 104 bytes (road,
# probability, route, DFA states, word: 8 each; the AV's belief, which is the true posterior
# here, 7 x 8); a level holds the children of its 4 observations in unfoldings.PEAK_COPIES = 4
# copies (1.7 kB), its decisions' keys (about 0.5 kB) and its words (24 bytes each, at most
# a few per history with their prefixes). Holding every word ever made instead adds about 160
# bytes per history seen: 30 levels of 2 x 300 children make that about 10 kB per budgeted
# history, past this bound by itself.
BYTES_PER_HISTORY = 4_000


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
def test_memory_per_budgeted_history_is_bounded_over_many_junctions(pomdp, name):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    policy = random_policy(pomdp, name)
    settings = EvaluationSettings(fallback_after=None, max_junctions=JUNCTIONS, max_nodes=BUDGET)
    # the same paths on a tenth of the budget first: what is loaded or cached once is not counted
    evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=JUNCTIONS,
                                                     max_nodes=BUDGET // 10))
    evaluation, peak = traced_peak(lambda: evaluate(pomdp, spec, policy, settings))
    assert evaluation.max_frontier == BUDGET and evaluation.nodes > 25 * BUDGET
    assert peak < BYTES_PER_HISTORY * BUDGET, f"{peak / BUDGET:.0f} bytes per history"


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
