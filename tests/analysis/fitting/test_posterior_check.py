"""The posterior-predictive check's simulator is the synthetic driver's step on given roads.

One row with one replicate draws exactly what a synthetic driver of the same seed draws on those
roads (initial trust, report, then per road takeover, the AV's performance, trust and report), so
the check simulates the driver the studies run, the AV's performance included; many rows show the
drawn performance at the model's failure rate.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from tests.analysis.fitting.test_fit_real import STUDY
from tests.policies.model.test_trust_pomdp import random_model
from trustroute.analysis.fitting import posterior_check as check_module
from trustroute.app.drivers import simulate
from trustroute.app.runs import posterior_check
from trustroute.core.dataset import read_roads
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver


def test_one_row_is_a_synthetic_driver_on_those_roads():
    model = random_model(np.random.default_rng(4), 7, performance_dependent=True, sparse=False)
    names = ["truck", "obstacle", "pedestrian", "none", "truck", "pedestrian"]
    incident = np.array([[model.incident_index(n) for n in names] + [0, 0]])
    mask = np.array([[True] * len(names) + [False, False]])
    for seed in range(10):
        sim = simulate(model, incident, mask, 0.7, 1, np.random.default_rng(seed))
        person = SyntheticDriver(model, np.random.default_rng(seed), report_accuracy=0.7)
        reports, takeovers, failures = [person.report_trust()], [], []
        for name in names:
            took_over = person.decides_takeover(name)
            performance = person.performance(name)
            person.move_trust(name, took_over, performance)
            takeovers.append(took_over)
            failures.append(performance == "fail")
            reports.append(person.report_trust())
        assert sim.takeover[0].tolist() == takeovers + [False, False]
        assert sim.failed[0].tolist() == failures + [False, False]
        assert sim.report[0].tolist() == reports + [reports[-1]] * 2


def test_the_avs_performance_is_drawn_from_the_model():
    model = random_model(np.random.default_rng(8), 7, performance_dependent=True, sparse=False)
    inc = model.incident_index("obstacle")
    n = 4000
    sim = simulate(model, np.full((1, 1), inc), np.ones((1, 1), dtype=bool), 1.0, n,
                   np.random.default_rng(1))
    # road 1's performance is drawn from θ_0 ~ π: P(fail) = Σ_θ π(θ) P(fail | θ, obstacle)
    p = float(model.initial_belief @ model.failure_probability[inc])
    fails = int(sim.failed.sum())
    assert stats.binomtest(fails, n, p).pvalue > 1e-4
    assert stats.binomtest(fails, n, min(p + 0.05, 1.0)).pvalue < 1e-4


def test_a_check_file_interrupted_while_it_is_written_leaves_the_old_file(tmp_path, monkeypatch):
    """Ctrl-C before the written check reaches the disk: the old file stays whole, nothing beside it."""
    import os

    import pytest

    from trustroute.analysis.fitting.posterior_check import write_check

    def interrupted(fd):
        raise KeyboardInterrupt

    path = tmp_path / "model.check.json"
    path.write_text('{"old": true}')
    monkeypatch.setattr(os, "fsync", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_check({"models": {"fitted": {"distance": 0.1}}, "_stats": {}}, path)
    assert path.read_text() == '{"old": true}'
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def _check_figure(tmp_path, monkeypatch):
    """The figure `fit --check` saves for the real study and the packaged model, and its file."""
    saved = []
    real = check_module.save_figure
    monkeypatch.setattr(check_module, "save_figure",
                        lambda fig, path, **kw: saved.append(fig) or real(fig, path, **kw))
    check = posterior_check(read_roads(STUDY), {"packaged": (load_driver_model(None), 0.8)}, 2,
                            np.random.default_rng(3))
    path = check_module.plot_check(check, tmp_path / "driver.check.png")
    (fig,) = saved
    return fig, path


def test_every_axis_of_the_check_figure_says_what_it_counts(tmp_path, monkeypatch):
    """The saved figure of `fit --check`: each panel names its x and y quantity, and the trust axes
    their unit (levels of the 1-7 scale)."""
    fig, path = _check_figure(tmp_path, monkeypatch)
    assert path.stat().st_size > 0 and len(fig.axes) == 4
    for ax in fig.axes:
        assert ax.get_title() and ax.get_xlabel().strip() and ax.get_ylabel().strip(), ax.get_title()
    trust_axes = [ax.get_xlabel() for ax in fig.axes if "trust" in ax.get_title()]
    assert len(trust_axes) == 2 and all("level" in label for label in trust_axes), trust_axes


def test_the_bars_of_each_value_are_centred_on_it(tmp_path, monkeypatch):
    """Every panel draws one bar a source (the real study, each model) at each value: the bars of
    a value are centred on that value, and the incidents' ticks stand at their bars' centre."""
    fig, _ = _check_figure(tmp_path, monkeypatch)
    for ax in fig.axes:
        centres = np.array([bar.get_x() + bar.get_width() / 2 for bar in ax.patches])
        per_value = centres.reshape(2, -1).mean(axis=0)   # drawn one source after another
        assert np.allclose(per_value, np.round(per_value)), (ax.get_title(), per_value)
    incidents = fig.axes[0]
    assert np.allclose(incidents.get_xticks(), np.arange(len(incidents.get_xticklabels())))
