"""`trustroute plan`: the power table, the minimal sizes and the power curve from simulated
studies of a config, sizes rounded to the Williams square, one-line errors for bad input; and the
simulated studies' outcomes are the model engine's (harness/study/planning.py)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from tests.cli import cli_json, run_cli
from trustroute.analysis.study.power import DEFAULT_TESTS
from trustroute.analysis.study.preregistration import chosen_size
from trustroute.core.errors import InputError
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.context import study_context
from trustroute.harness.study.planning import participant_sizes, planned_participants, simulate_studies


@pytest.fixture(scope="module")
def config_path(model_study):
    return model_study.parent / "study.toml"   # aware vs free on phi1, phi2; its policies cached


def test_sizes_are_rounded_to_the_williams_square():
    assert planned_participants(5, 4) == 8 and planned_participants(8, 4) == 8
    assert planned_participants(7, 3) == 12  # 3 cells: the square and its mirror, 6 rows
    assert participant_sizes("8:16:4", 4) == [8, 12, 16]
    assert participant_sizes("5:9", 4) == [8, 12]
    for bad in ("x", "8:4", "0:8", "1:2:3:4", "99999999999", "8:100001"):
        with pytest.raises(InputError):
            participant_sizes(bad, 4)


def test_plan_reports_power_with_intervals_and_the_minimal_size(config_path, capsys, tmp_path):
    # sizes above 13: Wilcoxon's p-value of fewer pairs with ties is scipy's exact permutation test
    # (2^N sign flips), seconds per study
    args = ("plan", str(config_path), "--participants", "14:40:12", "--simulations", "30",
            "--out", str(tmp_path), "--seed", "3")
    answer = cli_json(capsys, *args)
    assert answer["sizes"] == [16, 28, 40]
    rows = answer["power"]
    assert {(r["test"], r["spec"]) for r in rows} >= {("mcnemar", "phi1"), ("conditional_or", "phi2"),
                                                      ("wilcoxon", "all specs")}
    for row in rows:
        assert row["studies"] == 30 and row["power"] == row["rejected"] / 30
        assert row["low"] <= row["power"] <= row["high"]
    for found in answer["minimal_participants"]:
        powers = {r["participants"]: r["power"] for r in rows
                  if (r["test"], r["spec"]) == (found["test"], found["spec"])}
        if found["participants"] is None:
            assert powers[40] < 0.8
        else:
            assert all(p >= 0.8 for n, p in powers.items() if n >= found["participants"])
    assert (tmp_path / "power.png").stat().st_size > 0 and (tmp_path / "power.svg").exists()
    document = tmp_path / "prereg.md"
    again = cli_json(capsys, *args, "--preregistration", str(document))
    assert again["power"] == rows  # same seed, same answer
    _check_preregistration(document.read_text(), again)


def _check_preregistration(text: str, answer: dict) -> None:
    """The document's numbers are the plan's: its JSON block is the --json answer, its registered N
    the largest minimal size, and its power table that size's rows."""
    block = json.loads(text.split("```json\n", 1)[1].split("\n```", 1)[0])
    assert block == {k: v for k, v in answer.items() if k != "paths"}
    size = chosen_size(answer)
    if size is None:
        assert "**not determined**" in text
    else:
        assert f"**{size} participants**" in text
        for row in (r for r in answer["power"] if r["participants"] == size):
            interval = f"{row['power']:.3f} [{row['low']:.3f}, {row['high']:.3f}]"
            assert f"| {row['participants']} | {interval} |" in text
    assert answer["config_hash"] in text


def test_the_preregistration_names_the_study_it_registers(config_path, capsys, tmp_path):
    """The plan simulates on the model engine, but what it registers is the study as it will run:
    the hash `trustroute live` (or `study`) records for the config in study.json, and its engine.
    A live config planned gave the hash and the engine of its model-engine simulation."""
    live = tmp_path / "live.toml"
    live.write_text(config_path.read_text().replace('engine = "model"', 'engine = "live"'))
    config = load_study_config(live)
    assert config.engine == "live"
    document = tmp_path / "prereg.md"
    answer = cli_json(capsys, "plan", str(live), "--participants", "4", "--simulations", "10",
                      "--out", str(tmp_path), "--preregistration", str(document))
    assert answer["config_hash"] == config.content_hash
    assert answer["config_hash"] != config.with_overrides(engine="model").content_hash
    text = document.read_text()
    assert f"content hash `{config.content_hash}`" in text and "engine live." in text


def test_simulated_outcomes_follow_the_model_engine(config_path):
    """Satisfaction of the free condition and the reports as the per-episode study gives them (in
    distribution: the fixture's study of 12 participants sets the scale)."""
    config = load_study_config(config_path)
    sims = simulate_studies(study_context(config), 8, 100, np.random.default_rng(0))
    assert sims.satisfied.shape == (100, 8, 2, 2)
    rates = sims.satisfied.mean(axis=(0, 1))
    assert rates[0, 0] > 0.95 and 0.8 < rates[0, 1] < 0.95 and 0.7 < rates[1, 1] < 0.86
    assert np.isfinite(sims.reported).all() and 4.0 < sims.reported.mean() < 6.0


@pytest.mark.parametrize("args, where", [
    (("--participants", "9:3"), "--participants"),
    (("--driver", "no-such-driver.json"), "no-such-driver"),
])
def test_bad_input_is_one_line(config_path, capsys, tmp_path, args, where):
    code, out, err = run_cli(capsys, "plan", str(config_path), *args, "--out", str(tmp_path))
    assert code == 2 and err.count("\n") == 1 and where in err, err


def test_a_plan_folder_in_a_package_is_refused_before_any_simulation(config_path, capsys, tmp_path):
    """A package (its config and tables folder) is published read-only: the plan's folder in one is
    one line naming it, before the simulations, and nothing is written there."""
    package = tmp_path / "package"
    (package / "tables").mkdir(parents=True)
    (package / "study_config.json").write_text("{}")
    code, out, err = run_cli(capsys, "plan", str(config_path), "--out", str(package / "plan"))
    assert code == 2 and err.count("\n") == 1 and f"lies in the package {package}" in err, err
    assert sorted(p.name for p in package.rglob("*")) == ["study_config.json", "tables"]


REPO = Path(__file__).resolve().parents[2]
DEMO_PREREGISTRATION = REPO / "docs" / "preregistration_demo.md"


@pytest.mark.slow
def test_the_demo_preregistration_in_docs_is_plans_answer(capsys, tmp_path):
    """docs/preregistration_demo.md (written by `trustroute plan harness/study/examples/paper.toml
    --participants 8:60:4 --test mcnemar --test conditional_or --preregistration ...`): its tables
    and sample size are its JSON block's, and that block's rows at the registered size, the size
    where φ2 first reaches the target, are what `plan --json` answers today for that size alone
    (the simulated studies of one size do not depend on the other sizes tried)."""
    text = DEMO_PREREGISTRATION.read_text()
    block = json.loads(text.split("```json\n", 1)[1].split("\n```", 1)[0])
    _check_preregistration(text, block)
    reached = [found["participants"] for found in block["minimal_participants"] if found["participants"]]
    assert reached, "no planned test reaches the target in the document"
    size = min(reached)
    answer = cli_json(capsys, "plan", str(REPO / block["config_path"]), "--participants", str(size),
                      *[arg for test in block["tests"] for arg in ("--test", test)],
                      "--seed", str(block["seed"]), "--out", str(tmp_path))
    # the config's hash is of its settings and files' content, the same in every checkout
    assert answer["config_hash"] == block["config_hash"]
    assert answer["tests"] == block["tests"] and answer["sizes"] == [size]
    assert answer["power"] == [row for row in block["power"] if row["participants"] == size]


def test_each_power_row_names_the_effect_it_estimates(config_path, capsys, tmp_path):
    from trustroute.analysis.study.power import EFFECTS

    args = ("plan", str(config_path), "--participants", "8", "--simulations", "30", "--out", str(tmp_path))
    code, out, err = run_cli(capsys, *args)
    assert code == 0, err
    lines = out.splitlines()
    header = next(line for line in lines if line.startswith("test ") and "power [95% CI]" in line)
    assert "effect" in header.split() and "its median [2.5%, 97.5%]" in header
    table = lines[lines.index(header) + 2:]   # after the header's rule
    rows = table[:table.index("")]
    assert {row.split()[0] for row in rows} == set(DEFAULT_TESTS)
    for row in rows:
        assert f" {EFFECTS[row.split()[0]]} " in row, row
    answer = cli_json(capsys, *args)
    measures = {(r["test"], r["effect"]["measure"]) for r in answer["power"]}
    assert measures == {(t, EFFECTS[t]) for t in DEFAULT_TESTS}
    # docs/planning.md's table of the tests shows each test's effect in these words
    docs = (Path(__file__).resolve().parents[2] / "docs" / "planning.md").read_text()
    shown = dict(re.findall(r"^ *\| `(\w+)` \|.*\| ([^|]+) \|$", docs, re.M))
    assert {test: shown[test].strip() for test in EFFECTS} == EFFECTS
