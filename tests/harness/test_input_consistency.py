"""Every command validates a spec against its driver model the same way: through the one spec
loader (`load_spec` with the model's trust levels), so `spec check` rejects what `synth`,
`evaluate` and `run` reject, with the same one-line error."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli import run_cli
from tests.test_bad_input_matrix import five_trust_levels
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH

PHI1 = PACKAGED_SPECS / "phi1.toml"


def _commands(spec: Path, folder: Path, *driver: str) -> dict[str, list[str]]:
    """The commands that read a spec with a driver model (options that keep each one quick)."""
    return {
        "spec check": ["spec", "check", str(spec), *driver],
        "synth": ["synth", str(spec), *driver, "--horizon", "3", "--out", str(folder / "p.json")],
        "evaluate": ["evaluate", str(spec), "free", *driver, "--max-junctions", "8"],
        "run": ["run", str(spec), *driver, "--out", str(folder / "run")],
    }


def _one_line_error(capsys, args: list[str]) -> str:
    code, out, err = run_cli(capsys, *args)
    assert code == 2 and out == "", (args, out, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    return err.strip()


def test_six_coefficients_are_rejected_by_spec_check_as_by_synth(tmp_path, capsys):
    spec = tmp_path / "six.toml"
    spec.write_text(PHI1.read_text().replace("coeffs = [0, 0, 0, 0, 0, 1, 1]", "coeffs = [0, 0, 0, 0, 1, 1]"))
    errors = {name: _one_line_error(capsys, args) for name, args in _commands(spec, tmp_path).items()}
    line = spec.read_text().splitlines().index("coeffs = [0, 0, 0, 0, 1, 1]") + 1
    expected = (f"error: {spec}: line {line} column 1 (beliefs.hightrust): belief atom 'hightrust' has 6 "
                "coefficients but "
                "the driver model (default driver model) defines 7 trust levels")
    for name, error in errors.items():
        assert error.startswith(expected), (name, error)
    assert len(set(errors.values())) == 1
    assert list(tmp_path.iterdir()) == [spec]   # nothing written


def _five_level_model(path: Path) -> Path:
    data = json.loads(DEFAULT_DRIVER_MODEL_PATH.read_text())
    five_trust_levels(data)
    path.write_text(json.dumps(data))
    return path


def test_a_five_level_model_is_judged_the_same_by_every_command(tmp_path, capsys):
    """The model alone is valid (`model` shows it); with a 7-coefficient spec every command gives
    the same error; with a 5-coefficient spec they accept it."""
    driver = _five_level_model(tmp_path / "five.json")
    code, out, _ = run_cli(capsys, "model", "--driver", str(driver))
    assert code == 0 and "trust levels 1..5" in out
    errors = {name: _one_line_error(capsys, args)
              for name, args in _commands(PHI1, tmp_path, "--driver", str(driver)).items()}
    line = PHI1.read_text().splitlines().index("coeffs = [0, 0, 0, 0, 0, 1, 1]") + 1
    expected = (f"error: {PHI1}: line {line} column 1 (beliefs.hightrust): belief atom 'hightrust' has 7 "
                "coefficients but "
                f"the driver model ({driver}) defines 5 trust levels")
    for name, error in errors.items():
        assert error.startswith(expected), (name, error)
    five = tmp_path / "phi1_five.toml"
    five.write_text(PHI1.read_text().replace("coeffs = [1, 0, 0, 0, 0, 0, 0]", "coeffs = [1, 0, 0, 0, 0]")
                    .replace("coeffs = [0, 0, 0, 0, 0, 1, 1]", "coeffs = [0, 0, 0, 1, 1]"))
    for name in ("spec check", "evaluate"):
        code, _, err = run_cli(capsys, *_commands(five, tmp_path, "--driver", str(driver))[name])
        assert code == 0, (name, err)


@pytest.mark.parametrize("option", ["--driver", "--population"])
def test_spec_check_takes_the_model_it_checks_against(option, capsys):
    code, text, _ = run_cli(capsys, "spec", "check", "--help")
    assert code == 0 and option in text
