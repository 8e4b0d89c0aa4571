"""Studies with held-out drivers: true types drawn from a `[drivers] population`, logged, analysed.

- participant_type_indices: frequencies of 3000 participants within 4 SE of the weights (seeded),
  and a participant's type does not depend on how many participants the study has;
- a model-engine study with the packaged three-type population logs each participant's type in
  the `driver_type` column, resumes without duplicates, and its per-type tables equal a direct
  pandas computation on the episodes, their "all" rows the main tables' rows;
- a bad [drivers] table is a one-line error with exit code 2.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from tests.harness.helpers import run_study
from trustroute.analysis.study.analysis import study_analysis
from trustroute.analysis.study.per_type import ALL_TYPES
from trustroute.core.dataset import read_episodes
from trustroute.harness.cli import main
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.plan import participant_type_indices, participant_types
from trustroute.harness.study.runner import run_and_consolidate
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population


def _config_text(cache: Path, participants: int = 9, drivers: str | None = None) -> str:
    drivers = drivers if drivers is not None else f'[drivers]\npopulation = "{EXAMPLE_POPULATION_PATH}"\n'
    return f"""[study]
name = "types"
participants = {participants}
seed = 5
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
horizon = 4
policy_cache = "{cache}"

{drivers}"""


def test_true_types_follow_the_weights_and_are_stable_per_participant(tmp_path):
    path = tmp_path / "study.toml"
    path.write_text(_config_text(tmp_path / "cache", participants=3000))
    config = load_study_config(path)
    weights = load_driver_population(EXAMPLE_POPULATION_PATH).weights
    indices = participant_type_indices(config, weights)
    counts = np.bincount(indices, minlength=len(weights))
    se = np.sqrt(3000 * weights * (1 - weights))
    assert np.all(np.abs(counts - 3000 * weights) <= 4 * se), counts
    fewer = dataclasses.replace(config, participants=50)
    assert np.array_equal(participant_type_indices(fewer, weights), indices[:50])
    reseeded = dataclasses.replace(config, seed=6)
    assert not np.array_equal(participant_type_indices(reseeded, weights), indices)


@pytest.fixture(scope="module")
def type_study(tmp_path_factory):
    root = tmp_path_factory.mktemp("type-study")
    config = run_study(root / "study.toml", _config_text(root / "cache"), root / "out")
    return config, root / "out"


@pytest.mark.slow
def test_a_study_logs_true_types_and_resumes(type_study):
    config, out = type_study
    episodes = read_episodes(out)
    expected = participant_types(config)
    assert expected is not None and len(set(expected)) >= 2
    logged = episodes.groupby("participant")["driver_type"].unique()
    assert all(len(v) == 1 for v in logged)
    assert [logged[p][0] for p in range(config.participants)] == expected
    before = episodes.drop(columns=["wall_seconds"])
    run_and_consolidate(config, out, 1, None, progress=False, echo=lambda *_: None)
    after = read_episodes(out).drop(columns=["wall_seconds"])
    assert len(after) == len(before) == config.participants * 4
    assert after.equals(before)


@pytest.mark.slow
def test_per_type_tables_match_a_direct_computation(type_study):
    _, out = type_study
    analysis = study_analysis(out, "filter", resamples=200)
    episodes = analysis.episodes
    cells = analysis.per_type
    assert set(cells["driver_type"]) == {*episodes["driver_type"].unique(), ALL_TYPES}
    for (kind, spec, condition), group in episodes.groupby(["driver_type", "spec", "condition"]):
        row = cells[(cells["driver_type"] == kind) & (cells["spec"] == spec)
                    & (cells["condition"] == condition)]
        assert len(row) == 1
        row = row.iloc[0]
        assert row["n"] == len(group)
        assert row["satisfied"] == int(group["satisfied_filter"].sum())
        assert row["mean_trust"] == pytest.approx(group["mean_reported_trust"].mean())
        assert row["mean_true_trust"] == pytest.approx(group["mean_trust"].mean())
        assert row["participants"] == episodes[episodes["driver_type"] == kind]["participant"].nunique()
    overall = cells[cells["driver_type"] == ALL_TYPES]
    assert overall["n"].sum() == len(episodes)
    paired = analysis.per_type_paired
    for (kind, spec), group in episodes.groupby(["driver_type", "spec"]):
        wide = group.pivot_table(index="participant", columns="condition", values="satisfied_filter",
                                 aggfunc="first").astype(bool)
        row = paired[(paired["driver_type"] == kind) & (paired["spec"] == spec)].iloc[0]
        assert (row["condition_a"], row["condition_b"]) == ("aware", "free")
        assert row["pairs"] == len(wide)
        assert row["only_a_satisfied"] == int((wide["aware"] & ~wide["free"]).sum())
        assert row["only_b_satisfied"] == int((~wide["aware"] & wide["free"]).sum())
    # the overall rows are the study's own paired table and cells, every bootstrap interval included
    columns = list(analysis.paired.columns)
    mine = paired.loc[paired["driver_type"] == ALL_TYPES, columns].reset_index(drop=True)
    assert mine.astype(str).equals(analysis.paired.reset_index(drop=True).astype(str))
    assert analysis.paired["trust_diff_low"].notna().all()
    shown = [c for c in overall.columns if c in analysis.cells]
    assert overall[shown].reset_index(drop=True).astype(str).equals(analysis.cells[shown].astype(str))
    assert analysis.to_dict()["per_type"]


@pytest.mark.parametrize("drivers, words", [
    ('[drivers]\npopulation = "missing.json"\n', ["drivers.population", "missing.json"]),
    ('[drivers]\npopulation = 3\n', ["drivers.population"]),
    ('[drivers]\npopulation = "POP"\nweights = [1]\n', ["drivers.weights", "unknown key"]),
    ('[drivers]\npopulation = "BAD"\n', ["bad.json", "weights"]),
])
def test_bad_drivers_table_is_one_line(tmp_path, capsys, drivers, words):
    bad = tmp_path / "bad.json"
    bad.write_text(EXAMPLE_POPULATION_PATH.read_text().replace('"weight": 0.4', '"weight": 0.9'))
    drivers = drivers.replace("POP", str(EXAMPLE_POPULATION_PATH)).replace("BAD", str(bad))
    path = tmp_path / "study.toml"
    path.write_text(_config_text(tmp_path / "cache", drivers=drivers))
    with pytest.raises(SystemExit) as exit_info:
        main(["study", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for word in words:
        assert word in err, err
    assert not (tmp_path / "out").exists()
