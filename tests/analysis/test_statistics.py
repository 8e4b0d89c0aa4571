"""Statistics against brute force: exact McNemar, sign and Wilcoxon tests by enumeration, bootstrap
coverage, and the repeated-measures models (analysis/repeated_measures.py)."""

from __future__ import annotations

import itertools
import math
import os
import warnings

import numpy as np
import pytest

from trustroute.analysis.statistics import (
    BOOTSTRAP_DEGENERATE,
    BOOTSTRAP_PERCENTILE,
    bootstrap_ci,
    mcnemar_exact,
    wilcoxon_paired,
)


def _binomial_two_sided(k: int, n: int) -> float:
    probs = [math.comb(n, i) / 2**n for i in range(n + 1)]
    return min(1.0, sum(p for p in probs if p <= probs[k] * (1 + 1e-7)))


@pytest.mark.parametrize("seed", range(6))
def test_mcnemar_matches_enumeration(seed):
    rng = np.random.default_rng(seed)
    a = rng.random(30) < 0.7
    b = rng.random(30) < 0.5
    result = mcnemar_exact(a, b)
    only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
    assert (result.only_first, result.only_second) == (only_a, only_b)
    assert result.p_value == pytest.approx(_binomial_two_sided(only_a, only_a + only_b), rel=1e-9)


def test_mcnemar_no_discordant_pairs():
    same = np.array([True, False, True])
    assert mcnemar_exact(same, same).p_value == 1.0


def _wilcoxon_exact(x: np.ndarray, y: np.ndarray) -> float:
    d = x - y
    d = d[d != 0]
    ranks = np.argsort(np.argsort(np.abs(d))) + 1.0  # no ties in the test data
    observed = min(ranks[d > 0].sum(), ranks[d < 0].sum())
    total = 0
    count = 0
    for signs in itertools.product((0, 1), repeat=d.size):
        plus = sum(r for r, s in zip(ranks, signs, strict=True) if s)
        count += min(plus, ranks.sum() - plus) <= observed + 1e-9
        total += 1
    return count / total


@pytest.mark.parametrize("seed", range(4))
def test_wilcoxon_matches_enumeration(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(0.5, 1, 10)
    y = rng.normal(0, 1, 10)
    result = wilcoxon_paired(x, y)
    assert result.p_value == pytest.approx(_wilcoxon_exact(x, y), rel=1e-9)


def _flips_enumerated(d: np.ndarray) -> float:
    """Two-sided p of W+ over every sign vector of the nonzero differences, each listed (midranks
    for ties): 2 min(P(W+ >= w), P(W+ <= w)), at most 1."""
    from scipy.stats import rankdata

    d = d[d != 0]
    ranks = rankdata(np.abs(d))
    signs = np.array(list(itertools.product((0.0, 1.0), repeat=d.size)))
    sums = signs @ ranks
    observed = ranks[d > 0].sum()
    return min(1.0, 2 * min(np.mean(sums >= observed - 1e-9), np.mean(sums <= observed + 1e-9)))


def test_wilcoxon_with_ties_and_zeros_is_the_exact_sign_flip_test():
    """Trust reports (1-7) tie and repeat: up to 13 pairs the p-value is the exact one over every
    sign flip, equal to a listing of all flips and, bit for bit, to scipy's permutation test."""
    rng = np.random.default_rng(5)
    for case in range(150):
        n = int(rng.integers(2, 11))
        x, y = rng.integers(1, 8, n).astype(float), rng.integers(1, 8, n).astype(float)
        if (x == y).all():
            continue
        result = wilcoxon_paired(x, y)
        assert result.p_value == pytest.approx(_flips_enumerated(x - y), rel=1e-12, abs=1e-15), (x, y)
        if case % 10 == 0 or n == 10:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                reference = stats.wilcoxon(x, y, zero_method="wilcox")
            assert (result.p_value, result.statistic) == (float(reference.pvalue), float(reference.statistic))
    x13 = np.array([1, 2, 2, 3, 5, 7, 4, 4, 6, 1, 3, 2, 5], dtype=float)   # 13 pairs: scipy's last listing
    y13 = np.array([2, 2, 4, 1, 3, 4, 4, 6, 2, 3, 1, 5, 4], dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = stats.wilcoxon(x13, y13, zero_method="wilcox")
    assert wilcoxon_paired(x13, y13).p_value == float(reference.pvalue)


def test_sign_test_is_the_binomial_test_of_the_signs():
    """Mean satisfaction differences tie heavily: the sign test counts the positive and the negative
    ones, drops the zeros (and NaN) and is the exact binomial test at 1/2, here by enumeration and
    by scipy's binomtest."""
    from trustroute.analysis.statistics import sign_test

    rng = np.random.default_rng(8)
    for _ in range(60):
        n = int(rng.integers(1, 30))
        d = rng.choice([-1.0, -0.5, 0.0, 0.0, 0.5, 1.0, np.nan], n)
        positive, negative = int(np.sum(d > 0)), int(np.sum(d < 0))
        result = sign_test(d)
        assert (result.positive, result.negative, result.zero) == (positive, negative, int(np.sum(d == 0)))
        expected = 1.0 if positive + negative == 0 else _binomial_two_sided(positive, positive + negative)
        assert result.p_value == pytest.approx(expected, rel=1e-9)
        if positive + negative:
            assert result.p_value == pytest.approx(stats.binomtest(positive, positive + negative).pvalue)
    six_of_six = sign_test(np.array([0.5] * 6 + [0.0] * 15))   # 6 ahead, none behind, 15 tied
    assert six_of_six.p_value == pytest.approx(2 * 0.5**6)


def test_keyed_generators_depend_on_the_seed_and_key_alone():
    """A key's draws are the same in any order, in another process (another str hash seed) and
    for no other key or seed."""
    import subprocess
    import sys

    from trustroute.analysis.statistics import keyed_rng

    key = ("trust difference", "phi1", "aware", "free")
    first = keyed_rng(7, *key).random(3).tolist()
    keyed_rng(7, "satisfaction difference", "all specs", "aware", "free").random(100)
    assert keyed_rng(7, *key).random(3).tolist() == first
    assert keyed_rng(8, *key).random(3).tolist() != first
    assert keyed_rng(7, *key[:3], "robust").random(3).tolist() != first
    assert keyed_rng(7, "trust difference", "phi1aware", "free").random(3).tolist() != first
    # one other process, whose str hashes differ from this one's (checked: else it proves nothing)
    code = ("from trustroute.analysis.statistics import keyed_rng; "
            f"print(keyed_rng(7, *{key!r}).random(3).tolist()); print(hash({key[0]!r}))")
    hash_seed = "2" if os.environ.get("PYTHONHASHSEED") == "1" else "1"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONHASHSEED": hash_seed}).stdout.splitlines()
    assert out[0] == repr(first) and int(out[1]) != hash(key[0])


def test_wilcoxon_all_equal_and_nan_pairs():
    assert wilcoxon_paired(np.ones(5), np.ones(5)).p_value == 1.0
    x = np.array([1.0, 2.0, np.nan, 4.0, 5.0, 7.0])
    y = np.array([0.0, 1.5, 3.0, 1.0, 2.0, 1.0])
    assert wilcoxon_paired(x, y).pairs == 5


def test_bootstrap_is_seeded_and_covers_the_mean():
    rng = np.random.default_rng(0)
    values = rng.random(50) < 0.8
    assert bootstrap_ci(values, np.random.default_rng(1), 2000) == bootstrap_ci(
        values, np.random.default_rng(1), 2000
    )
    hits = 0
    trials = 150
    for _ in range(trials):
        sample = (rng.random(80) < 0.8).astype(float)
        low, high, method = bootstrap_ci(sample, rng, 1000)
        assert method == BOOTSTRAP_PERCENTILE
        hits += low <= 0.8 <= high
    # percentile bootstrap of a proportion at n=80: coverage close to 0.95 (binomial noise of 150 trials)
    assert 0.86 <= hits / trials <= 0.995


def test_bootstrap_edge_cases():
    low, high, method = bootstrap_ci(np.array([]), np.random.default_rng(0))
    assert math.isnan(low) and math.isnan(high) and method == ""
    assert bootstrap_ci(np.ones(10), np.random.default_rng(0), 100) == (1.0, 1.0, BOOTSTRAP_DEGENERATE)
    big = np.random.default_rng(0).random(100_000)
    low, high, _ = bootstrap_ci(big, np.random.default_rng(0), 200)
    assert low < big.mean() < high and high - low < 0.01


# -- intervals, effect sizes, repeated-measures models ---------------------------------------------

from scipy import stats  # noqa: E402

from trustroute.analysis.repeated_measures import conditional_logit, mixed_trust_model  # noqa: E402
from trustroute.analysis.statistics import (  # noqa: E402
    PairedTable,
    conditional_odds_ratio,
    mean_difference,
    paired_risk_difference,
    paired_table,
    rate_interval,
)


def test_all_of_21_exact_interval():
    low, high = rate_interval(21, 21)
    assert round(low, 3) == 0.839 and high == 1.0
    low, high = rate_interval(0, 21)
    assert low == 0.0 and round(high, 3) == 0.161


@pytest.mark.parametrize("method", ["exact", "wilson"])
def test_rate_interval_matches_binomtest_on_random_inputs(method):
    rng = np.random.default_rng(7)
    for _ in range(50):
        n = int(rng.integers(1, 300))
        k = int(rng.integers(0, n + 1))
        level = float(rng.choice([0.8, 0.9, 0.95, 0.99]))
        expected = stats.binomtest(k, n).proportion_ci(confidence_level=level, method=method)
        assert rate_interval(k, n, level, method) == pytest.approx((expected.low, expected.high), abs=1e-12)


def test_exact_interval_against_beta_quantiles():
    # Clopper–Pearson from its definition: Beta quantiles (an independent computation).
    for k, n in [(0, 5), (3, 10), (18, 21), (17, 21), (50, 50)]:
        low = 0.0 if k == 0 else stats.beta.ppf(0.025, k, n - k + 1)
        high = 1.0 if k == n else stats.beta.ppf(0.975, k + 1, n - k)
        assert rate_interval(k, n) == pytest.approx((low, high), abs=1e-7)


def test_rate_interval_bad_input():
    assert all(math.isnan(v) for v in rate_interval(0, 0))
    with pytest.raises(ValueError):
        rate_interval(5, 3)
    with pytest.raises(ValueError):
        rate_interval(1, 3, method="wald")


def test_risk_difference_covers_by_monte_carlo():
    rng = np.random.default_rng(3)
    # paired outcomes: a shared participant effect makes them correlated
    hits, trials, truth = 0, 300, 0.0
    for _ in range(trials):
        frailty = rng.random(21)
        a, b = rng.random(21) < 0.5 + 0.3 * (frailty - 0.5), rng.random(21) < 0.5 + 0.3 * (frailty - 0.5)
        estimate = paired_risk_difference(paired_table(a, b))
        assert estimate.low <= estimate.value <= estimate.high
        hits += estimate.low <= truth <= estimate.high
    assert 0.9 <= hits / trials <= 1.0


def test_risk_difference_and_odds_ratio_from_counts():
    table = PairedTable(both=10, only_first=6, only_second=1, neither=4)
    rd = paired_risk_difference(table)
    assert rd.value == pytest.approx(5 / 21)
    assert -1 <= rd.low < rd.value < rd.high <= 1
    odds = conditional_odds_ratio(table)
    assert odds.value == 6.0
    p_low, p_high = rate_interval(6, 7)
    assert (odds.low, odds.high) == pytest.approx((p_low / (1 - p_low), p_high / (1 - p_high)))
    assert conditional_odds_ratio(PairedTable(5, 3, 0, 2)).high == math.inf
    assert math.isnan(conditional_odds_ratio(PairedTable(5, 0, 0, 2)).value)


def test_mean_difference_bootstrap_is_seeded_and_covers():
    rng = np.random.default_rng(0)
    x, y = rng.normal(4.6, 1, 21), rng.normal(4.4, 1, 21)
    one = mean_difference(x, y, np.random.default_rng(5), 2000)
    assert one == mean_difference(x, y, np.random.default_rng(5), 2000)
    assert one.value == pytest.approx(float(np.mean(x - y)))
    assert one.low < one.value < one.high
    same = mean_difference(np.ones(5), np.ones(5), rng)
    assert (same.value, same.low, same.high) == (0.0, 0.0, 0.0)


def test_conditional_logit_recovers_an_effect_and_respects_participants():
    rng = np.random.default_rng(11)
    participants = np.repeat(np.arange(300), 4)
    treated = np.tile([1, 0, 1, 0], 300)
    spec = np.tile([0, 0, 1, 1], 300)
    person = rng.normal(0, 1.0, 300)[participants]
    logit = -0.2 + 1.0 * treated + person
    outcome = rng.random(participants.size) < 1 / (1 + np.exp(-logit))
    effect = conditional_logit(outcome, treated, participants, spec)
    assert effect.low < math.e < effect.high
    assert effect.p_value < 1e-3 and effect.groups <= 300
    none = conditional_logit(np.ones(8), np.tile([1, 0], 4), np.repeat(np.arange(4), 2))
    assert math.isnan(none.estimate) and "no participant" in none.note


def test_mixed_model_recovers_a_difference():
    rng = np.random.default_rng(12)
    participants = np.repeat(np.arange(60), 4)
    treated = np.tile([1, 0, 1, 0], 60)
    value = 4.4 + 0.3 * treated + rng.normal(0, 1, 60)[participants] + rng.normal(0, 0.3, 240)
    effect = mixed_trust_model(value, treated, participants, np.tile([0, 0, 1, 1], 60))
    assert effect.low < 0.3 < effect.high and effect.p_value < 1e-3


# -- separation: detected from the data, and what is estimable reported with its reason ----------

from trustroute.analysis.repeated_measures import EXACT_MODEL, separation  # noqa: E402
from trustroute.analysis.statistics import exact_odds_ratio, median_unbiased_proportion  # noqa: E402


def _binomial_tail_at_least(k: int, n: int, p: float) -> float:
    """P(X >= k) for X ~ Binomial(n, p) by enumeration (independent of scipy)."""
    return sum(math.comb(n, j) * p**j * (1 - p) ** (n - j) for j in range(k, n + 1))


def _paired_design(pattern: list[tuple[int, int]], specs: int = 2):
    """Episodes of participants who drive each spec under A (treated) and B: pattern[i] gives the
    (A, B) outcomes of participant i, repeated for every spec unless a spec-specific list is given."""
    outcome, treated, participant, spec = [], [], [], []
    for person, cells in enumerate(pattern):
        for s in range(specs):
            a, b = cells[s] if isinstance(cells[0], tuple) else cells
            outcome += [a, b]
            treated += [1, 0]
            participant += [person, person]
            spec += [s, s]
    return (np.array(outcome, float), np.array(treated, float), np.array(participant), np.array(spec))


def _issue_like_data():
    """21 participants x 2 specs; 6 participants differ, all of them in favour of the treated one."""
    pattern = [[(1, 0), (1, 1)]] * 3 + [[(1, 1), (1, 0)]] * 3
    pattern += [[(1, 1), (1, 1)]] * 10 + [[(0, 0), (0, 0)]] * 5
    return _paired_design(pattern)


def test_median_unbiased_proportion_by_enumeration():
    for k, n in [(0, 6), (6, 6), (3, 10), (1, 7), (20, 21)]:
        p = median_unbiased_proportion(k, n)
        if k == n:
            assert _binomial_tail_at_least(n, n, p) == pytest.approx(0.5)
        elif k == 0:
            assert 1 - _binomial_tail_at_least(1, n, p) == pytest.approx(0.5)
        else:  # the log-odds midpoint of the two one-sided 50 % limits
            low = stats.beta.ppf(0.5, k, n - k + 1)
            high = stats.beta.ppf(0.5, k + 1, n - k)
            assert _binomial_tail_at_least(k, n, low) == pytest.approx(0.5)
            assert 1 - _binomial_tail_at_least(k + 1, n, high) == pytest.approx(0.5)
            odds = math.sqrt(low / (1 - low) * high / (1 - high))
            assert p / (1 - p) == pytest.approx(odds)


def test_exact_odds_ratio_interval_by_enumeration():
    for b, c in [(6, 0), (0, 4), (5, 2)]:
        estimate = exact_odds_ratio(b, c)
        n = b + c
        if b > 0:  # lower limit: P(X >= b | p_low) = 0.025
            p_low = estimate.low / (1 + estimate.low)
            assert _binomial_tail_at_least(b, n, p_low) == pytest.approx(0.025, abs=1e-9)
        else:
            assert estimate.low == 0.0
        if c > 0:  # upper limit: P(X <= b | p_high) = 0.025
            p_high = estimate.high / (1 + estimate.high)
            assert 1 - _binomial_tail_at_least(b + 1, n, p_high) == pytest.approx(0.025, abs=1e-9)
        else:
            assert estimate.high == math.inf
        assert math.isfinite(estimate.value) and estimate.low <= estimate.value <= estimate.high


def test_paired_odds_ratio_on_one_sided_pairs_is_median_unbiased_with_its_reason():
    odds = conditional_odds_ratio(PairedTable(5, 3, 0, 2), sides=("aware", "free"))
    assert math.isfinite(odds.value) and odds.value == pytest.approx(0.5 ** (1 / 3) / (1 - 0.5 ** (1 / 3)))
    assert odds.high == math.inf and "all 3 discordant pairs favour aware" in odds.note
    single = conditional_odds_ratio(PairedTable(5, 1, 0, 2), sides=("aware", "free"))
    assert single.note.startswith("the one discordant pair favours aware (b / c = inf)"), single.note
    reverse = conditional_odds_ratio(PairedTable(5, 0, 2, 2), sides=("aware", "free"))
    assert reverse.low == 0.0 and 0 < reverse.value < 1 and "favour free" in reverse.note
    assert conditional_odds_ratio(PairedTable(10, 6, 1, 4)).note == ""


def test_separation_detected_complete_quasi_and_none():
    outcome, treated, participant, spec = _issue_like_data()
    exog = np.column_stack([treated, spec])
    assert separation(outcome, exog, participant).kind != "none"
    assert separation(outcome, exog, participant).favours == "treated"
    # complete: every participant succeeds under A and fails under B
    outcome, treated, participant, _ = _paired_design([(1, 0)] * 5, specs=1)
    assert separation(outcome, treated[:, None], participant).kind == "complete"
    # quasi: a participant with two A episodes, one failed, ties with the failed B episode
    outcome = np.array([1, 0, 0, 1, 0, 1, 0], float)
    treated = np.array([1, 1, 0, 1, 0, 1, 0], float)
    participant = np.array([0, 0, 0, 1, 1, 2, 2])
    found = separation(outcome, treated[:, None], participant)
    assert (found.kind, found.favours) == ("quasi", "treated")
    # none: discordant pairs both ways
    outcome, treated, participant, _ = _paired_design([(1, 0)] * 5 + [(0, 1)] * 2, specs=1)
    assert separation(outcome, treated[:, None], participant).kind == "none"
    # control side
    outcome, treated, participant, _ = _paired_design([(0, 1)] * 4 + [(1, 1)] * 3, specs=1)
    assert separation(outcome, treated[:, None], participant).favours == "control"


def test_conditional_logit_on_separated_data_reports_the_exact_effect_and_why():
    from statsmodels.discrete.conditional_models import ConditionalLogit

    outcome, treated, participant, spec = _issue_like_data()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = ConditionalLogit(outcome, np.column_stack([treated, spec]), groups=participant).fit(disp=False)
    assert fit.params[0] > 5  # statsmodels runs off towards an infinite odds ratio
    effect = conditional_logit(outcome, treated, participant, spec, sides=("aware", "free"))
    assert effect.model == EXACT_MODEL
    assert effect.estimate == pytest.approx(exact_odds_ratio(6, 0).value)
    assert math.isfinite(effect.estimate) and effect.high == math.inf
    assert effect.low == pytest.approx(exact_odds_ratio(6, 0).low) and effect.low > 1
    assert effect.p_value == pytest.approx(2 * 0.5**6)  # the exact two-sided binomial test
    assert "separation" in effect.note and "favour aware" in effect.note and "(6 / 0)" in effect.note


def test_conditional_logit_without_separation_matches_statsmodels():
    from statsmodels.discrete.conditional_models import ConditionalLogit

    pattern = [[(1, 0), (1, 1)]] * 4 + [[(0, 1), (1, 1)]] * 2 + [[(1, 1), (0, 0)]] * 6
    outcome, treated, participant, spec = _paired_design(pattern)
    effect = conditional_logit(outcome, treated, participant, spec)
    # statsmodels' fit to convergence (Newton; its default BFGS stops short of the maximum)
    fit = ConditionalLogit(outcome, np.column_stack([treated, spec]), groups=participant).fit(
        disp=False, method="newton")
    assert effect.model == "conditional logit" and effect.note == ""
    assert effect.estimate == pytest.approx(math.exp(fit.params[0]))
    z = stats.norm.ppf(0.975)
    assert effect.high == pytest.approx(math.exp(fit.params[0] + z * fit.bse[0]))
    assert effect.p_value == pytest.approx(fit.pvalues[0])


def test_a_stratum_without_discordance_is_left_out_with_its_reason():
    from statsmodels.discrete.conditional_models import ConditionalLogit

    # phi1: 5 pairs favour A, 2 favour B; phi2: every episode satisfied (its dummy is separated)
    pattern = [[(1, 0), (1, 1)]] * 5 + [[(0, 1), (1, 1)]] * 2 + [[(0, 0), (1, 1)]] * 8
    outcome, treated, participant, spec = _paired_design(pattern)
    effect = conditional_logit(outcome, treated, participant, spec)
    assert "1 left out (every episode satisfied" in effect.note and effect.observations == outcome.size
    # the limit of the full fit: the fit on the stratum with discordance, which is b / c here
    first = spec == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # statsmodels drops the participants without variance
        alone = ConditionalLogit(outcome[first], treated[first][:, None],
                                 groups=participant[first]).fit(disp=False, method="newton")
    assert effect.estimate == pytest.approx(math.exp(alone.params[0])) == pytest.approx(5 / 2, rel=1e-12)
    assert effect.p_value == pytest.approx(alone.pvalues[0])


def test_paired_odds_ratio_without_discordant_pairs_says_why():
    odds = conditional_odds_ratio(PairedTable(8, 0, 0, 4))
    assert math.isnan(odds.value) and "no discordant pair" in odds.note


def test_holm_adjusts_one_family_as_statsmodels_does():
    from statsmodels.stats.multitest import multipletests

    from trustroute.analysis.statistics import holm

    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    p = [0.2, 0.001, 0.04, 0.5, 0.012]
    assert holm(p) == pytest.approx(list(multipletests(p, method="holm")[1]))
    assert holm([0.02]) == [0.02]                        # one pair: nothing to adjust
    assert holm([None, 0.01, float("nan"), 0.02]) == [None, 0.02, None, 0.02]


def test_conditional_logit_with_a_specs_effect_infinite_reports_the_matched_pairs():
    """Two informative participants, one ahead under A on φ1, one ahead under B on φ2, the rest all
    satisfied or all not (a study of 12 drivers of the three packaged types): the spec's coefficient
    runs off to infinity while the treatment's stays finite, Newton's information matrix is
    singular, and the row shows the matched pairs' exact conditional effect (b = c = 1) instead of
    an empty 'fit failed'."""
    pattern = [[(0, 0), (0, 1)], [(1, 0), (1, 1)]] + [[(0, 0), (0, 0)]] * 6 + [[(1, 1), (1, 1)]] * 4
    outcome, treated, participant, spec = _paired_design(pattern)
    assert separation(outcome, np.column_stack([treated, spec]), participant).kind == "none"
    effect = conditional_logit(outcome, treated, participant, spec, sides=("aware", "free"))
    assert effect.model == EXACT_MODEL
    assert effect.estimate == pytest.approx(exact_odds_ratio(1, 1).value) == pytest.approx(1.0)
    assert effect.low == pytest.approx(exact_odds_ratio(1, 1).low)
    assert effect.p_value == pytest.approx(1.0)   # the exact two-sided binomial test of 1 of 2
    assert "singular" in effect.note and "(1 / 1)" in effect.note
