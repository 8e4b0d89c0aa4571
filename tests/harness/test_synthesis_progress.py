"""Every synthesis a command runs shows its progress on stderr once it has run PROGRESS_AFTER
seconds (away from a terminal: a line at a time, with the current bounds), and `--quiet` or
`--json` silences it. The threshold is set to 0 here so that the small problems of a test count
as long ones."""

from __future__ import annotations

import json
import re

import pytest

from tests.cli import run_cli
from trustroute.core.wording import interval, outward
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH
from trustroute.policies import resolve


@pytest.fixture
def at_once(monkeypatch):
    monkeypatch.setattr(resolve, "PROGRESS_AFTER", 0.0)


def _bound_lines(err: str, prefix: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith(prefix) and "L=" in line and "U=" in line]


def test_synth_shows_rounds_with_bounds_and_quiet_silences_them(tmp_path, capsys, at_once):
    code, out, err = run_cli(capsys, "synth", "phi2", "--horizon", "10", "--out", str(tmp_path / "a.json"))
    assert code == 0, err
    assert _bound_lines(err, "synthesizing phi2: "), err
    code, out, err = run_cli(capsys, "synth", "phi2", "--horizon", "10", "--out", str(tmp_path / "b.json"),
                             "--quiet")
    assert code == 0 and err == "" and "policy written to" in out
    code, out, err = run_cli(capsys, "synth", "phi2", "--horizon", "10", "--out", str(tmp_path / "c.json"),
                             "--json")
    assert code == 0 and err == "" and json.loads(out)["lower"] > 0


def test_a_short_synthesis_prints_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(resolve, "PROGRESS_AFTER", 3600.0)
    code, _, err = run_cli(capsys, "synth", "phi2", "--horizon", "10", "--out", str(tmp_path / "a.json"))
    assert code == 0 and err == ""


def test_population_synth_announces_every_run(tmp_path, capsys, at_once):
    code, _, err = run_cli(capsys, "synth", "phi1", "--horizon", "3", "--population",
                           str(EXAMPLE_POPULATION_PATH), "--objective", "robust", "--time-limit", "30",
                           "--out", str(tmp_path / "r.json"))
    assert code == 0, err
    runs = [line for line in err.splitlines() if line.startswith("synth: [")]
    # within 3 junctions no route satisfies phi1: the per-type bounds and the Bayes run, each with
    # its place, time and bounds, prove the robust value 0, and the one line after them says that
    # the candidate priors are not run
    assert len(runs) == 5 and all(line.count("[") >= 2 for line in runs[:4]), err
    assert "the other 15 candidate priors are not run" in runs[4], err


@pytest.mark.parametrize("command", [("evaluate", "phi1", "aware"), ("run", "phi1", "--policy", "aware")])
def test_a_command_synthesizing_aware_shows_it(command, tmp_path, capsys, at_once):
    code, _, err = run_cli(capsys, *command, "--cache-dir", str(tmp_path / "c1"))
    assert code == 0, err
    assert _bound_lines(err, "synthesizing aware for phi1: "), err
    code, _, err = run_cli(capsys, *command, "--cache-dir", str(tmp_path / "c2"), "--quiet")
    assert code == 0 and err == ""


def test_a_cached_population_policy_announces_its_runs(tmp_path, capsys, town, at_once):
    from trustroute.participants.driver_population import load_driver_population
    from trustroute.policies.logic.spec import load_spec

    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    spec = load_spec("phi1", town, population.types[0].model.n_trust)
    resolve.population_policy(town, population, spec, "robust",
                              resolve.PolicySettings(tmp_path / "c", horizon=3, progress=True))
    err = capsys.readouterr().err
    assert [line for line in err.splitlines() if line.startswith("synthesizing robust for phi1: [")], err
    resolve.population_policy(town, population, spec, "robust",
                              resolve.PolicySettings(tmp_path / "d", horizon=3, progress=False))
    assert capsys.readouterr().err == ""


def test_bounds_are_printed_rounded_outward(capsys, at_once):
    # a lower bound just below 1 must not read as 1: the printed interval holds the certified one
    on_round = resolve._progress_lines("synthesizing x")
    on_round(0.99999, 0.12341)
    assert "L=0.9999 U=0.1235" in capsys.readouterr().err
    assert outward(0.99999996, 0.99999996, 6) == ("0.999999", "1.000000")
    assert interval(0.0, 1e-12) == "[0.000000, 0.000001]"
    assert interval(0.25, 0.25) == "[0.250000, 0.250000]"


def test_progress_says_when_there_is_no_lower_bound_yet(tmp_path, capsys, at_once, monkeypatch):
    """The trust-state synthesis' L is a valued policy's: the rounds before the first policy is
    valued (the unbounded U's) say there is none yet instead of printing L=0.0000."""
    monkeypatch.setattr(resolve, "PROGRESS_EVERY", 0.0)   # a line every round
    code, _, err = run_cli(capsys, "synth", "phi1_trust", "--work-limit", "300000", "--out",
                           str(tmp_path / "t.json"))
    assert code == 0, err
    lines = [line for line in err.splitlines() if line.startswith("synthesizing phi1_trust: ")]
    assert "L not yet (no policy valued) U=1.0000" in lines[0], err
    assert not [line for line in lines if "L=0.0000" in line], err
    valued = [float(lower) for line in lines for lower in re.findall(r"L=([0-9.]+)", line)]
    lower = json.loads((tmp_path / "t.json").read_text())["lower"]   # the policy's certified L
    assert valued and abs(max(valued) - lower) <= 1e-4, (valued, lower)   # four decimals shown


def test_a_robust_synthesis_prints_every_bound_rounded_outward():
    """The population synthesis' lines round each certified bound outward, the lone lower ones (a
    worst type's value, "certified >=") down too: values a hair below 0.3, 0.4, 0.5 do not read as
    them."""
    from types import SimpleNamespace

    from trustroute.harness.commands.synth import population_lines

    below, above = (lambda x: x - 4e-8), (lambda x: x + 4e-8)
    kinds = [SimpleNamespace(name="a", weight=0.5, lower=below(0.5), upper=above(0.5), exact=True),
             SimpleNamespace(name="b", weight=0.5, lower=below(0.3), upper=above(0.6), exact=False)]
    found = SimpleNamespace(lower=below(0.3), upper=above(0.3), gap=8e-8, seconds=1.0, type_values=kinds,
                            mixture_value=(below(0.4), above(0.55)), worst_type_value=below(0.3),
                            prior=(0.5, 0.5), population=SimpleNamespace(weights=(0.5, 0.5)),
                            bayes_lower=below(0.4), bayes_upper=above(0.4), candidates=[{}],
                            candidates_not_needed=0, candidates_skipped=0)
    lines = population_lines("phi", 2, "robust", found, worst_bayes=below(0.2))
    assert lines[0].startswith("phi (2 driver types, objective robust): 0.299999 <= max worst type's "
                               "P(satisfied) <= 0.300001 "), lines[0]
    assert ("a (weight 0.5) exact [0.499999, 0.500001]; b (weight 0.5) certified [0.299999, 0.600001]"
            in lines[1])
    assert "[0.399999, 0.550001]; worst type 0.299999;" in lines[2], lines[2]
    assert lines[3] == ("Bayes-optimal synthesis beside it: 0.399999 <= prior-weighted <= 0.400001, its "
                        "worst type 0.199999; robust value certified >= 0.299999 (best of 1 candidate "
                        "prior), <= 0.300001")
