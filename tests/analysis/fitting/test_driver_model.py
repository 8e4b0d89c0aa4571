"""Fitting recovers a known driver model from synthetic logs.

Data: model-engine episodes of the default driver model on random routes (30 junctions, so every
incident type and many trust levels are visited). Stated tolerances, on rows the data actually
inform (at least 500 expected visits; ~9 SE of a single entry apart at that count is excluded):
- noisy reports (accuracy 0.8), EM: every entry of those T rows within 0.08 of the truth,
  takeover probabilities with >= 500 visits within 0.08, report accuracy within 0.02;
- exact reports, counts: within 0.07.
The generic starting point of EM is checked to be far outside these tolerances, so the test can fail.
1000 noisy episodes inform 11 rows and 11 takeover entries (>= 10 asked for); transition rows
pulled 15% toward uniform in the M-step, or a report accuracy pinned at 0.9, fail the EM test.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest

from tests.study_tables import set_values, study_copy
from trustroute.analysis.fitting.driver_model import fit_roads, observations_from_roads, starting_parameters
from trustroute.core.dataset import ROADS_FILE, frame_from_table
from trustroute.harness.cli import main
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import run_model_episode
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.protocol import RoutingPolicy

MIN_VISITS = 500
TOLERANCE_EM = 0.08
TOLERANCE_COUNTS = 0.07


class RandomRoutes(RoutingPolicy):
    """A uniformly random next junction at every road, drawn from `rng`."""

    name = "random"

    def __init__(self, town, rng):
        self.town, self.rng = town, rng

    def next_junction(self, context):
        actions = self.town.actions(context.road)
        return actions[int(self.rng.integers(len(actions)))]


def _logs(town, driver, episodes, accuracy, seed):
    spec = load_spec("specs/phi2_strict.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec, junction_cap=30, fallback_after=None)
    rng = np.random.default_rng(seed)
    # The episodes' Arrow tables, concatenated and converted to pandas once: the same frame as
    # concatenating each episode's DataFrame, without a thousand small table-to-pandas conversions.
    tables = [
        run_model_episode(
            setup, RandomRoutes(town, rng), SyntheticDriver(driver, rng, accuracy), f"e{i:05d}", 0
        ).tables()["roads"]
        for i in range(episodes)
    ]
    return frame_from_table(pa.concat_tables(tables))


def _row_errors(result, driver):
    informed = result.row_weight >= MIN_VISITS
    errors = np.abs(result.parameters.transition - driver.trust_transition).max(axis=-1)
    return informed, errors


@pytest.mark.slow
def test_em_recovers_transition_rows_from_noisy_reports(town, driver):
    roads = _logs(town, driver, 1000, 0.8, seed=11)
    assert {"trust_before", "trust_after"} <= set(roads.columns)  # present, but never read by fit
    result = fit_roads(roads.drop(columns=["trust_before", "trust_after"]), driver, "em", 300)
    informed, errors = _row_errors(result, driver)
    assert informed.sum() >= 10, "too few informed rows for a meaningful test"
    assert errors[informed].max() <= TOLERANCE_EM
    visits = result.row_weight.sum(axis=(1, 2))
    takeover_error = np.abs(result.parameters.takeover - driver.takeover_probability)[visits >= MIN_VISITS]
    assert takeover_error.size >= 10 and takeover_error.max() <= TOLERANCE_EM
    assert abs(result.report_accuracy - 0.8) <= 0.02
    # the generic start is far from the truth on the same rows: recovery is not an artefact
    start = starting_parameters(
        len(driver.incident_types), driver.n_trust, observations_from_roads(roads, driver)
    )
    assert np.abs(start.transition - driver.trust_transition).max(axis=-1)[informed].max() > 3 * TOLERANCE_EM
    # the log-likelihood never decreases (EM)
    assert all(b >= a - 1e-6 for a, b in zip(result.history, result.history[1:], strict=False))
    model = result.model()
    assert model.trust_levels == driver.trust_levels


@pytest.mark.slow
def test_counts_recover_rows_from_exact_reports(town, driver):
    roads = _logs(town, driver, 800, 1.0, seed=12)
    result = fit_roads(roads, driver, "counts")
    informed, errors = _row_errors(result, driver)
    assert informed.sum() >= 8
    assert errors[informed].max() <= TOLERANCE_COUNTS


def test_counts_refuse_missing_reports(town, driver):
    roads = _logs(town, driver, 5, 0.8, seed=1)
    roads.loc[roads["index"] == 2, "reported_trust"] = -1
    from trustroute.core.errors import InputError

    with pytest.raises(InputError, match="no trust report"):
        fit_roads(roads, driver, "counts")


def test_fit_errors_name_the_study_s_roads_file(model_study, tmp_path):
    """An error about the logs names the roads table of the study fitted, directory and all."""
    from trustroute.analysis.fitting.driver_model import fit_study
    from trustroute.core.errors import InputError

    roads_file = study_copy(model_study, tmp_path / "unreported", ROADS_FILE,
                            set_values("reported_trust", None, [2])) / ROADS_FILE
    with pytest.raises(InputError, match="no trust report") as info:
        fit_study(roads_file.parent, method="counts")
    assert info.value.source == str(roads_file)
    roads_file = study_copy(model_study, tmp_path / "meteor", ROADS_FILE,
                            set_values("incident", "meteor", [2])) / ROADS_FILE
    with pytest.raises(InputError, match="meteor") as info:
        fit_study(roads_file.parent)
    assert info.value.source == str(roads_file)


@pytest.mark.slow
def test_fit_cli_writes_a_valid_driver_model(model_study, tmp_path, capsys):
    out = tmp_path / "driver.json"
    with pytest.raises(SystemExit) as info:
        main(["fit", str(model_study), "--out", str(out), "--json", "--iterations", "30"])
    payload = json.loads(capsys.readouterr().out)
    assert info.value.code == 0
    assert payload["method"] == "em" and payload["paths"] == {"driver_model": str(out)}
    model = load_driver_model(out)
    assert model.n_trust == 7 and "fitted by trustroute fit" in model.provenance


def test_a_fit_of_a_model_without_a_trust_free_table_reads_back(town, driver):
    """A base model that leaves out the optional trust-free table gives a fitted file that loads
    (an empty table would lack every incident's entry)."""
    import dataclasses

    from trustroute.participants.driver_model import driver_model_from_dict

    base = dataclasses.replace(driver, trust_free_takeover_probability={})
    result = fit_roads(_logs(town, base, 5, 1.0, seed=2), base, "counts")
    document = result.model_dict()
    assert "trust_free_takeover_probability" not in document
    fitted = driver_model_from_dict(json.loads(json.dumps(document)), "<fitted>")
    assert fitted.trust_levels == driver.trust_levels
