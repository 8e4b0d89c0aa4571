"""Driver populations sampled from [population] settings: seeded, valid, and the CLI around them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trustroute.harness.cli import main
from trustroute.participants.driver_model import driver_model_from_dict
from trustroute.participants.driver_population import load_driver_population
from trustroute.participants.population import PopulationConfig
from trustroute.participants.sampled_types import sample_driver_population

SPREAD = PopulationConfig(concentration=20.0, takeover_spread=1.0)


def test_sampling_is_seeded_and_each_type_is_a_valid_model(driver):
    first = sample_driver_population(driver, 4, SPREAD, np.random.default_rng(7))
    again = sample_driver_population(driver, 4, SPREAD, np.random.default_rng(7))
    other = sample_driver_population(driver, 4, SPREAD, np.random.default_rng(8))
    assert first.content_hash == again.content_hash != other.content_hash
    assert first.n_types == 4 and np.allclose(first.weights, 0.25)
    hashes = {t.model.content_hash for t in first.types}
    assert len(hashes) == 4  # the types differ from each other
    for t in first.types:
        model = driver_model_from_dict(t.model.to_dict(), "roundtrip")  # validates every row
        assert model.content_hash != driver.content_hash
        # zeros of the nominal rows stay zeros; takeover probabilities 0 and 1 stay fixed
        assert np.all(t.model.trust_transition[driver.trust_transition == 0] == 0)
        fixed = (driver.takeover_probability == 0) | (driver.takeover_probability == 1)
        assert np.array_equal(t.model.takeover_probability[fixed], driver.takeover_probability[fixed])


def test_population_sample_and_show_cli(tmp_path, capsys):
    out = tmp_path / "pop.json"
    with pytest.raises(SystemExit) as exit_info:
        main(["population", "sample", "--types", "3", "--seed", "4", "--concentration", "30",
              "--takeover-spread", "0.7", "--out", str(out), "--json"])
    assert exit_info.value.code == 0
    payload = json.loads(capsys.readouterr().out)
    population = load_driver_population(out)
    assert payload["paths"] == {"population": str(out)}
    assert [t["name"] for t in payload["types"]] == list(population.names)
    with pytest.raises(SystemExit) as exit_info:
        main(["population", "show", str(out), "--json"])
    assert exit_info.value.code == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["content_hash"] == population.content_hash
    assert [t["weight"] for t in shown["types"]] == pytest.approx([1 / 3] * 3)
    # the same seed writes the same file
    again = tmp_path / "again.json"
    with pytest.raises(SystemExit):
        main(["population", "sample", "--types", "3", "--seed", "4", "--concentration", "30",
              "--takeover-spread", "0.7", "--out", str(again), "--json"])
    capsys.readouterr()
    assert again.read_bytes() == out.read_bytes()


@pytest.mark.parametrize("n_types", [3, 49])
def test_population_sample_says_the_hash_the_file_it_writes_loads_with(n_types, tmp_path, capsys):
    """49 weights of 1/49 sum to 1 - 1e-16: the file loads them divided by their sum, and the hash
    `sample` says is that population's, the one a policy file records."""
    out = tmp_path / "pop.json"
    with pytest.raises(SystemExit):
        main(["population", "sample", "--types", str(n_types), "--seed", "1", "--concentration", "30",
              "--out", str(out), "--json"])
    said = json.loads(capsys.readouterr().out)
    loaded = load_driver_population(out)
    assert said["content_hash"] == loaded.content_hash
    assert [t["weight"] for t in said["types"]] == list(loaded.weights)


def _one_line_error(capsys, argv, *words):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for word in words:
        assert word in err, err


def test_bad_population_settings_are_one_line_errors(tmp_path, capsys):
    out = str(tmp_path / "pop.json")
    _one_line_error(capsys, ["population", "sample", "--types", "2", "--seed", "1", "--out", out],
                    "error: --concentration: concentration inf and takeover spread 0 give every type "
                    "the nominal model (fix: ")
    config = tmp_path / "settings.toml"
    config.write_text("[population]\nreport_accuracy = 0.9\n")
    _one_line_error(capsys, ["population", "sample", "--types", "2", "--seed", "1", "--config",
                             str(config), "--out", out],
                    f"error: {config}: population: concentration inf and takeover spread 0 give")
    config.write_text("[population]\nconcentration = -1\n")
    _one_line_error(capsys, ["population", "sample", "--types", "2", "--seed", "1", "--config",
                             str(config), "--out", out], "settings.toml", "population.concentration")
    _one_line_error(capsys, ["population", "sample", "--types", "0", "--seed", "1", "--out", out],
                    "--types")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "trustroute-driver-population", "version": 1, "types": []}))
    _one_line_error(capsys, ["population", "show", str(bad)], "bad.json", "types")
    assert not (tmp_path / "pop.json").exists()


def test_population_sample_help_says_a_spread_is_needed_and_its_defaults(capsys):
    """Only --types, --seed and --out are required options, yet the defaults of the spread are
    refused: the help says which option is needed and what each spread option defaults to."""
    with pytest.raises(SystemExit):
        main(["population", "sample", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert ("Needs a spread: a finite --concentration, a --takeover-spread above 0, or a --config "
            "whose [population] table gives one.") in text
    assert "default: --config's, else inf, the nominal rows" in text
    assert "default: --config's, else 0)" in text
