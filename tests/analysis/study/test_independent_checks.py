"""Every figure of the paired, cell, takeover and order tables against a computation that shares no
code with the analysis: counts by pandas, exact tests by binomial and sign-flip enumeration,
Wilson and Clopper–Pearson intervals from statsmodels, Newcombe's interval written from the paper,
Holm from statsmodels, BCa by Efron and Tibshirani's formulas on the bootstrap's own draws,
Cochran's Q and Friedman by their formulas, the mixed model against statsmodels and OLS."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from scipy.special import ndtri
from statsmodels.stats.multitest import multipletests
from statsmodels.stats.proportion import proportion_confint

from tests.analysis.study.made_episodes import made_episodes
from trustroute.analysis.statistics import keyed_rng
from trustroute.analysis.study.canonical import participant_ranks
from trustroute.core.dataset import read_episodes, read_roads

SEED = 20240513
RESAMPLES = 2000


def binomial_two_sided(k: int, n: int) -> float:
    """The exact two-sided binomial test at 1/2, by enumeration."""
    if n == 0:
        return 1.0
    masses = [math.comb(n, i) / 2**n for i in range(n + 1)]
    return min(1.0, sum(m for m in masses if m <= masses[k] * (1 + 1e-9)))


def signed_rank_enumerated(difference: np.ndarray) -> float:
    """Wilcoxon's two-sided p over every sign vector of the nonzero differences (midranks), each
    listed: 2 min(P(W+ >= w), P(W+ <= w)), at most 1."""
    nonzero = difference[difference != 0]
    ranks = stats.rankdata(np.abs(nonzero))
    observed, m = ranks[nonzero > 0].sum(), nonzero.size
    at_least = at_most = 0
    for start in range(0, 2**m, 1 << 16):
        ids = np.arange(start, min(2**m, start + (1 << 16)), dtype=np.int64)
        sums = ((ids[:, None] >> np.arange(m)) & 1) @ ranks
        at_least += int(np.sum(sums >= observed - 1e-9))
        at_most += int(np.sum(sums <= observed + 1e-9))
    return min(1.0, 2 * min(at_least, at_most) / 2**m)


def wilson(k: int, n: int) -> tuple[float, float]:
    return proportion_confint(k, n, alpha=0.05, method="wilson")


def clopper_pearson(k: int, n: int) -> tuple[float, float]:
    return proportion_confint(k, n, alpha=0.05, method="beta")


def newcombe_paired(a: int, b: int, c: int, d: int) -> tuple[float, float, float]:
    """Newcombe (1998), paired proportions, method 10: Wilson limits of both margins combined with
    the phi coefficient of the 2x2 table (0 when a margin is empty)."""
    n = a + b + c + d
    p1, p2 = (a + b) / n, (a + c) / n
    (l1, u1), (l2, u2) = wilson(a + b, n), wilson(a + c, n)
    margins = (a + b) * (c + d) * (a + c) * (b + d)
    phi = (a * d - b * c) / math.sqrt(margins) if margins else 0.0
    below = math.sqrt((p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2)
    above = math.sqrt((u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2)
    return p1 - p2, max(-1.0, p1 - p2 - below), min(1.0, p1 - p2 + above)


def bootstrap_means(data: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The means of the resamples scipy.stats.bootstrap draws from `rng` (one batch: indices of
    shape (resamples, n))."""
    return data[rng.integers(0, data.size, (RESAMPLES, data.size))].mean(axis=1)


def bca(data: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    """Efron and Tibshirani (1993), 14.3: bias correction from the share of resampled means below
    the mean (ties counted half), acceleration from the jackknife means."""
    means = bootstrap_means(data, rng)
    theta = data.mean()
    z0 = ndtri((np.sum(means < theta) + np.sum(means <= theta)) / (2 * means.size))
    jackknife = (data.sum() - data) / (data.size - 1)
    spread = jackknife.mean() - jackknife
    acceleration = np.sum(spread**3) / (6 * np.sum(spread**2) ** 1.5)
    levels = [stats.norm.cdf(z0 + (z0 + z) / (1 - acceleration * (z0 + z)))
              for z in (ndtri(0.025), ndtri(0.975))]
    return tuple(np.percentile(means, [100 * level for level in levels]))


def test_the_paired_tables_of_three_conditions_against_an_independent_computation():
    from trustroute.analysis.study.paired import (
        ALL_SPECS,
        all_pairs_table,
        condition_pairs,
        per_participant_table,
    )

    conditions = ("aware", "robust", "free")
    episodes = made_episodes(participants=21, conditions=conditions, seed=8)
    table = all_pairs_table(per_participant_table(episodes, "satisfied", conditions),
                            condition_pairs(conditions), ["phi1", "phi2"], SEED, RESAMPLES)
    assert len(table) == 9
    for _, row in table.iterrows():
        a_side, b_side, spec = row["condition_a"], row["condition_b"], row["spec"]
        wide = episodes.pivot_table(index=["participant", "spec"], columns="condition",
                                    values=["satisfied", "mean_reported_trust"], aggfunc="first")
        if spec != ALL_SPECS:
            cell = wide.xs(spec, level="spec")
            first, second = cell[("satisfied", a_side)].astype(bool), cell[("satisfied", b_side)].astype(bool)
            a, b = int((first & second).sum()), int((first & ~second).sum())
            c, d = int((~first & second).sum()), int((~first & ~second).sum())
            assert (row["both_satisfied"], row["only_a_satisfied"], row["only_b_satisfied"],
                    row["neither_satisfied"], row["pairs"]) == (a, b, c, d, 21)
            assert row["mcnemar_p"] == pytest.approx(binomial_two_sided(b, b + c), rel=1e-9)
            assert (row["risk_difference"], row["rd_low"], row["rd_high"]) == pytest.approx(
                newcombe_paired(a, b, c, d), abs=1e-12)
            low, high = clopper_pearson(b, b + c)
            assert (row["odds_ratio"], row["or_low"], row["or_high"]) == pytest.approx(
                (b / c, low / (1 - low), high / (1 - high)), rel=1e-7)
            trust = cell["mean_reported_trust"]
            difference = (trust[a_side] - trust[b_side]).to_numpy()
        else:
            person = (wide[("satisfied", a_side)].astype(float) - wide[("satisfied", b_side)].astype(float)
                      ).groupby(level="participant").mean().to_numpy()
            ahead, behind = int(np.sum(person > 0)), int(np.sum(person < 0))
            assert (row["a_ahead"], row["b_ahead"]) == (ahead, behind)
            assert row["sign_test_p"] == pytest.approx(binomial_two_sided(ahead, ahead + behind), rel=1e-9)
            assert row["risk_difference"] == pytest.approx(person.mean(), abs=1e-12)
            assert (row["rd_low"], row["rd_high"]) == pytest.approx(
                bca(person, keyed_rng(SEED, "satisfaction difference", spec, a_side, b_side)), abs=1e-12)
            difference = (wide[("mean_reported_trust", a_side)] - wide[("mean_reported_trust", b_side)]
                          ).groupby(level="participant").mean().to_numpy()
        assert row["trust_difference"] == pytest.approx(difference.mean(), abs=1e-12)
        assert (row["trust_diff_low"], row["trust_diff_high"]) == pytest.approx(
            bca(difference, keyed_rng(SEED, "trust difference", spec, a_side, b_side)), abs=1e-12)
        assert row["median_trust_difference"] == pytest.approx(np.median(difference))
        # 21 pairs of whole-number reports, ties and zeros: the exact p, not the normal approximation
        assert row["wilcoxon_p"] == pytest.approx(signed_rank_enumerated(difference), rel=1e-9)
    for test in ("mcnemar_p", "sign_test_p", "wilcoxon_p"):
        for _, rows in table.dropna(subset=[test]).groupby("spec"):
            assert rows[f"{test}_holm"].to_numpy(dtype=float) == pytest.approx(
                multipletests(rows[test].to_numpy(dtype=float), method="holm")[1], rel=1e-12)


def test_wilcoxon_is_exact_with_ties_beyond_thirteen_pairs_and_marked_where_approximate():
    """scipy's Wilcoxon is exact only without ties and zeros (or up to 13 pairs): reported trust
    has both, and on 21 participants its normal approximation is off by about 0.01. The p-value is
    the exact one up to WILCOXON_EXACT_PAIRS differences; beyond, the approximation, said so."""
    from trustroute.analysis.statistics import (
        WILCOXON_APPROXIMATE,
        WILCOXON_EXACT,
        WILCOXON_EXACT_PAIRS,
        wilcoxon_paired,
    )
    from trustroute.analysis.study.display import APPROXIMATE_MARK, wilcoxon_p_column

    rng = np.random.default_rng(21)
    for n in (14, 17, 21):
        first, second = rng.integers(1, 8, n).astype(float), rng.integers(1, 8, n).astype(float)
        result = wilcoxon_paired(first, second)
        assert result.method == WILCOXON_EXACT
        assert result.p_value == pytest.approx(signed_rank_enumerated(first - second), rel=1e-9)
    # without ties the exact p is scipy's exact test
    first, second = rng.normal(size=40), rng.normal(size=40)
    assert wilcoxon_paired(first, second).p_value == pytest.approx(
        stats.wilcoxon(first, second, method="exact").pvalue, rel=1e-9)
    many = WILCOXON_EXACT_PAIRS + 20
    first = rng.integers(1, 8, many).astype(float)
    second = first + rng.choice([-2.0, -1.0, 1.0, 2.0], many)   # no zero difference, ties
    beyond = wilcoxon_paired(first, second)
    assert beyond.method == WILCOXON_APPROXIMATE
    assert beyond.p_value == pytest.approx(stats.wilcoxon(first, second, method="asymptotic").pvalue)
    methods = [beyond.method, WILCOXON_EXACT, beyond.method]
    frame = pd.DataFrame({"wilcoxon_p": [beyond.p_value, 0.5, None], "wilcoxon_method": methods})
    shown = wilcoxon_p_column(frame, "wilcoxon_p")
    assert shown[0].startswith(APPROXIMATE_MARK) and not shown[1].startswith(APPROXIMATE_MARK)
    assert not shown[2].startswith(APPROXIMATE_MARK)


def _trust_design(participant_sd: float, seed: int, participants: int = 21):
    rng = np.random.default_rng(seed)
    participant = np.repeat(np.arange(participants), 4)
    treated = np.tile([1.0, 0.0, 1.0, 0.0], participants)
    spec = np.tile(["phi1", "phi1", "phi2", "phi2"], participants)
    person = rng.normal(0, participant_sd, participants)[participant]
    value = 4.8 + 0.2 * treated - 0.3 * (spec == "phi2") + person + rng.normal(0, 1.2, participant.size)
    return value, treated, participant, spec


def _profile_reml(value: np.ndarray, exog: np.ndarray, participant: np.ndarray, ratio: float) -> float:
    """The REML log likelihood, up to a constant, with the variances' ratio `ratio` and the fixed
    effects and residual variance profiled out: V = I + ratio ZZ' built whole, no shortcut."""
    z = (participant[:, None] == np.unique(participant)[None, :]).astype(float)
    v_inverse = np.linalg.inv(np.eye(len(value)) + ratio * z @ z.T)
    gram = exog.T @ v_inverse @ exog
    residual = value - exog @ np.linalg.solve(gram, exog.T @ v_inverse @ value)
    free = len(value) - exog.shape[1]
    return -0.5 * (free * np.log(residual @ v_inverse @ residual / free)
                   - np.linalg.slogdet(v_inverse)[1] + np.linalg.slogdet(gram)[1])


def test_the_mixed_model_is_statsmodels_reml_fit_where_it_converges():
    import statsmodels.api as sm
    from statsmodels.regression.mixed_linear_model import MixedLM

    from trustroute.analysis.repeated_measures import mixed_trust_model

    value, treated, participant, spec = _trust_design(participant_sd=1.0, seed=4)
    exog = np.column_stack([np.ones_like(value), treated, spec == "phi2"]).astype(float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = MixedLM(value, exog, groups=participant).fit(reml=True)
    assert fit.converged
    effect = mixed_trust_model(value, treated, participant, spec)
    assert effect.estimate == pytest.approx(fit.params[1], abs=1e-6) and effect.note == ""
    # the covariance of the fixed effects: GLS with the fitted variance ratio (scale from the fit)
    ratio = float(np.asarray(fit.cov_re).ravel()[0]) / fit.scale
    sigma = np.kron(np.eye(21), np.eye(4) + ratio * np.ones((4, 4)))
    gls = sm.GLS(value, exog, sigma=sigma).fit()
    z = stats.norm.ppf(0.975)
    assert (effect.low, effect.high) == pytest.approx(
        (gls.params[1] - z * gls.bse[1], gls.params[1] + z * gls.bse[1]), abs=1e-5)
    assert effect.p_value == pytest.approx(2 * stats.norm.sf(abs(gls.params[1] / gls.bse[1])), abs=1e-5)
    assert gls.bse[1] == pytest.approx(fit.bse[1], rel=5e-3)   # statsmodels' own (observed) information


def test_the_mixed_model_with_its_participants_variance_at_zero_is_least_squares_and_says_so():
    """Participants who hardly differ put the REML optimum on its boundary, a variance of 0: the
    profile REML likelihood, computed here with dense matrices, is highest there, above the point
    statsmodels' MixedLM stops at (short of the boundary; whether it says it converged there
    differs between processors). The fit is then least squares, and the note says why."""
    import statsmodels.api as sm
    from statsmodels.regression.mixed_linear_model import MixedLM

    from trustroute.analysis.repeated_measures import BOUNDARY_NOTE, mixed_trust_model

    value, treated, participant, spec = _trust_design(participant_sd=0.0, seed=2)
    exog = np.column_stack([np.ones_like(value), treated, spec == "phi2"]).astype(float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = MixedLM(value, exog, groups=participant).fit(reml=True)
    stopped_at = float(np.asarray(fit.cov_re).ravel()[0]) / fit.scale
    at_zero = _profile_reml(value, exog, participant, 0.0)
    assert math.isfinite(stopped_at) and at_zero >= _profile_reml(value, exog, participant, stopped_at)
    assert all(at_zero > _profile_reml(value, exog, participant, ratio)
               for ratio in np.geomspace(1e-6, 10, 30))
    ols = sm.OLS(value, exog).fit()
    effect = mixed_trust_model(value, treated, participant, spec)
    z = stats.norm.ppf(0.975)
    assert effect.estimate == pytest.approx(ols.params[1], abs=1e-9)
    assert (effect.low, effect.high) == pytest.approx(
        (ols.params[1] - z * ols.bse[1], ols.params[1] + z * ols.bse[1]), abs=1e-9)
    assert effect.p_value == pytest.approx(2 * stats.norm.sf(abs(ols.tvalues[1])), rel=1e-9)
    assert effect.note == BOUNDARY_NOTE


def test_the_conditional_logit_against_its_likelihood_maximised_by_hand():
    """The conditional likelihood of each participant's outcomes given how many succeeded, summed
    over every arrangement, maximised by scipy; the standard error from its numerical Hessian.
    statsmodels' default optimiser (BFGS) stops with a gradient of about 1e-3 on these data, an odds
    ratio 3e-4 off the maximum, which shows in a table's third decimal; Newton's method reaches it."""
    import itertools

    from scipy.optimize import minimize

    from trustroute.analysis.repeated_measures import conditional_logit

    episodes = made_episodes(participants=30, conditions=("aware", "free"), seed=1)
    outcome = episodes["satisfied"].to_numpy(dtype=float)
    treated = (episodes["condition"] == "aware").to_numpy(dtype=float)
    exog = np.column_stack([treated, (episodes["spec"] == "phi2").to_numpy(dtype=float)])
    groups = []
    for rows in episodes.groupby("participant").indices.values():
        k = int(outcome[rows].sum())
        if 0 < k < len(rows):
            groups.append((exog[rows], outcome[rows] == 1, list(itertools.combinations(range(len(rows)), k))))

    def negative_log_likelihood(beta):
        total = 0.0
        for x, success, arrangements in groups:
            eta = x @ beta
            total -= eta[success].sum() - np.logaddexp.reduce([eta[list(c)].sum() for c in arrangements])
        return total

    beta = minimize(negative_log_likelihood, np.zeros(2), method="BFGS", options={"gtol": 1e-10}).x
    h, hessian = 1e-4, np.zeros((2, 2))
    for i, j in itertools.product(range(2), repeat=2):
        e_i, e_j = np.eye(2)[i] * h, np.eye(2)[j] * h
        hessian[i, j] = (negative_log_likelihood(beta + e_i + e_j) - negative_log_likelihood(beta + e_i - e_j)
                         - negative_log_likelihood(beta - e_i + e_j)
                         + negative_log_likelihood(beta - e_i - e_j)) / (4 * h * h)
    se = math.sqrt(np.linalg.inv(hessian)[0, 0])
    effect = conditional_logit(outcome, treated, episodes["participant"].to_numpy(),
                               episodes["spec"].to_numpy())
    assert effect.model == "conditional logit" and effect.groups == len(groups)
    z = stats.norm.ppf(0.975)
    assert effect.estimate == pytest.approx(math.exp(beta[0]), rel=1e-7)
    assert (effect.low, effect.high) == pytest.approx(
        (math.exp(beta[0] - z * se), math.exp(beta[0] + z * se)), rel=1e-4)
    assert effect.p_value == pytest.approx(2 * stats.norm.sf(abs(beta[0] / se)), rel=1e-4)


def test_a_studys_cells_takeovers_and_order_tables_against_an_independent_computation(model_study):
    from trustroute.analysis.study.analysis import study_analysis

    analysis = study_analysis(model_study, "filter", resamples=RESAMPLES)
    episodes = pd.read_parquet(model_study / "episodes.parquet")
    # the analysis' order of the rows: participants by the digest of their data (canonical.py)
    ranks = participant_ranks(read_episodes(model_study), read_roads(model_study))
    episodes = episodes.iloc[np.argsort(episodes["participant"].map(ranks).to_numpy(), kind="stable")]
    episodes = episodes.reset_index(drop=True)
    satisfied = episodes["satisfied"].astype(bool)   # the filter source is the logged outcome
    for _, row in analysis.cells.iterrows():
        group = episodes[(episodes["spec"] == row["spec"]) & (episodes["condition"] == row["condition"])]
        k, n = int(satisfied[group.index].sum()), len(group)
        assert (row["n"], row["satisfied"]) == (n, k)
        assert (row["ci_low"], row["ci_high"]) == pytest.approx(clopper_pearson(k, n), abs=1e-9)
        assert (row["wilson_low"], row["wilson_high"]) == pytest.approx(wilson(k, n), abs=1e-12)
        trust = group["mean_reported_trust"].astype(float)
        assert row["mean_trust"] == pytest.approx(trust.mean(), abs=1e-12)
        means = bootstrap_means(trust.dropna().to_numpy(), keyed_rng(SEED, "mean reported trust", row["spec"],
                                                                      row["condition"]))
        assert (row["trust_ci_low"], row["trust_ci_high"]) == pytest.approx(np.percentile(means, [2.5, 97.5]),
                                                                            abs=1e-12)
        for column, logged in (("mean_true_trust", "mean_trust"), ("mean_final_trust", "final_trust"),
                               ("mean_junctions", "junctions"), ("takeovers_per_episode", "takeovers")):
            assert row[column] == pytest.approx(group[logged].astype(float).mean(), abs=1e-12)
    roads = pd.read_parquet(model_study / "roads.parquet")
    driven = roads[roads["index"] > 0].merge(episodes[["episode_id", "condition"]], on="episode_id")
    for _, row in analysis.takeovers.iterrows():
        group = driven[(driven["incident"] == row["incident"]) & (driven["condition"] == row["condition"])]
        k = int(group["takeover"].astype(bool).sum())
        assert (row["roads"], row["takeovers"]) == (len(group), k)
        assert (row["ci_low"], row["ci_high"]) == pytest.approx(clopper_pearson(k, len(group)), abs=1e-9)
    for _, row in analysis.order.iterrows():
        group = episodes[episodes["position"] == row["position"] - 1]
        assert (row["n"], row["satisfied"]) == (len(group), int(satisfied[group.index].sum()))
    by_position = episodes.assign(sat=satisfied.astype(int)).pivot_table(
        index="participant", columns="position", values="sat", aggfunc="first").to_numpy()
    k_, columns, rows = by_position.shape[1], by_position.sum(axis=0), by_position.sum(axis=1)
    q = (k_ - 1) * (k_ * np.sum(columns**2) - rows.sum() ** 2) / (k_ * rows.sum() - np.sum(rows**2))
    assert analysis.order_tests["cochran_q_p"] == pytest.approx(stats.chi2.sf(q, k_ - 1), rel=1e-9)
    trust = episodes.pivot_table(index="participant", columns="position", values="mean_reported_trust",
                                 aggfunc="first").dropna().to_numpy()
    n_, k_ = trust.shape
    ranks = np.apply_along_axis(stats.rankdata, 1, trust)
    chi2 = 12 / (n_ * k_ * (k_ + 1)) * np.sum(ranks.sum(axis=0) ** 2) - 3 * n_ * (k_ + 1)
    ties = sum(float(np.sum(t**3 - t)) for t in (np.unique(r, return_counts=True)[1] for r in trust))
    chi2 /= 1 - ties / (n_ * k_ * (k_**2 - 1))
    assert analysis.order_tests["friedman_p"] == pytest.approx(stats.chi2.sf(chi2, k_ - 1), rel=1e-9)


def test_questionnaire_scores_alpha_and_paired_tests_with_holm_against_an_independent_computation(tmp_path):
    """Three conditions: the scores (mean of the items, reversed ones turned), their SD and
    Cronbach's alpha by their formulas, Wilcoxon by enumeration, and each p-value's Holm value over
    the pairs of conditions, as every paired p-value of the report has."""
    from trustroute.analysis.study.display import questionnaire_test_display
    from trustroute.analysis.study.paired import condition_pairs
    from trustroute.analysis.study.questionnaires import questionnaire_tables
    from trustroute.harness.live.answers import write_answer_table

    conditions = ("aware", "robust", "free")
    rng = np.random.default_rng(6)
    episodes, rows = [], []
    for person in range(12):
        for k, condition in enumerate(conditions):
            episode = f"p{person:05d}-phi1-{condition}"
            episodes.append({"episode_id": episode, "participant": person, "condition": condition})
            for index in range(4):
                rows.append({"participant": person, "episode_id": episode, "placement": "after_trial",
                             "questionnaire": "jian", "item": f"item{index}", "item_index": index,
                             "value": float(np.clip(rng.integers(1, 8) + k, 1, 7)), "reversed": index == 3,
                             "scale_min": 1.0, "scale_max": 7.0, "answered_utc": "2026-01-01T00:00:00Z"})
    write_answer_table(tmp_path, rows)
    scores, tests = questionnaire_tables(tmp_path, pd.DataFrame(episodes), condition_pairs(conditions))
    answers = pd.DataFrame(rows)
    answers["turned"] = np.where(answers["reversed"], 8 - answers["value"], answers["value"])
    items = answers.pivot_table(index="episode_id", columns="item_index", values="turned")
    items["condition"] = [e.rsplit("-", 1)[1] for e in items.index]
    items["participant"] = [int(e[1:6]) for e in items.index]
    for _, row in scores.iterrows():
        group = items[items["condition"] == row["condition"]]
        matrix = group[[0, 1, 2, 3]].to_numpy()
        alpha = 4 / 3 * (1 - matrix.var(axis=0, ddof=1).sum() / matrix.sum(axis=1).var(ddof=1))
        assert row["responses"] == 12 and row["mean_score"] == pytest.approx(matrix.mean(), abs=1e-12)
        assert row["sd_score"] == pytest.approx(matrix.mean(axis=1).std(ddof=1), abs=1e-12)
        assert row["cronbach_alpha"] == pytest.approx(alpha, abs=1e-12)
    score = items.assign(score=items[[0, 1, 2, 3]].mean(axis=1)).pivot_table(
        index="participant", columns="condition", values="score")
    assert len(tests) == 3
    for _, row in tests.iterrows():
        assert row["wilcoxon_p"] == pytest.approx(
            signed_rank_enumerated((score[row["a"]] - score[row["b"]]).to_numpy()), rel=1e-9)
    assert tests["wilcoxon_p_holm"].to_numpy(dtype=float) == pytest.approx(
        multipletests(tests["wilcoxon_p"].to_numpy(dtype=float), method="holm")[1], rel=1e-12)
    assert "Wilcoxon p (Holm)" in questionnaire_test_display(tests)
