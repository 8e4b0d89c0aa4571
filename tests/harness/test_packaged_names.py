"""One vocabulary: every SPEC, TOWN, DRIVER and POPULATION argument takes a path or a packaged name
(trustroute/core/packaged.py), on the command line, in the API, in study configs and in the gym env;
a bad name is one line, exit 2, with a hint that names what exists (run outside the repository)."""

from __future__ import annotations

import json

import pytest

import trustroute
from tests.cli import run_cli
from trustroute.core.packaged import SPECS
from trustroute.networks.town import TOWNS
from trustroute.participants.driver_model import DRIVER_MODELS
from trustroute.participants.driver_population import POPULATIONS


@pytest.fixture(autouse=True)
def outside_the_repository(tmp_path, monkeypatch):
    """Every test runs in an empty folder: a repository path such as specs/phi1.toml is missing."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_the_packaged_names():
    assert {"phi1", "phi2", "phi1_strict", "phi2_strict", "phi1_trust"} <= set(SPECS.names())
    assert TOWNS.names() == ["city", "csomor", "pentagon", "town01_carla"]
    assert DRIVER_MODELS.names() == ["driver_model", "driver_model_performance"]
    assert POPULATIONS.names() == ["driver_population_real", "driver_population_three_types"]
    assert SPECS.path("phi1.toml") == SPECS.path("phi1") and SPECS.path("specs/phi1.toml") is None
    assert TOWNS.path("nosuch") is None and TOWNS.resolve("nosuch").name == "nosuch"


def test_a_base_folder_reads_relative_names_there(outside_the_repository):
    """`resolve(value, base)`: a relative value is a file in `base` first, an absolute one is read
    as it is, and a name with no such file is still the packaged file of that name."""
    base = outside_the_repository / "sub"
    base.mkdir()
    (base / "driver_model.json").write_text("{}")
    assert DRIVER_MODELS.resolve("driver_model.json", base) == base / "driver_model.json"
    assert DRIVER_MODELS.resolve("driver_model.json") == DRIVER_MODELS.path("driver_model")
    assert DRIVER_MODELS.resolve("driver_model_performance", base) == DRIVER_MODELS.path(
        "driver_model_performance")
    assert DRIVER_MODELS.resolve(base / "driver_model.json", outside_the_repository / "elsewhere") == (
        base / "driver_model.json")
    assert DRIVER_MODELS.resolve("gone.json", base) == base / "gone.json"


GOOD = [
    ["synth", "phi1", "--horizon", "3", "--town", "town01_carla", "--driver", "driver_model",
     "--out", "p.json", "--json"],
    ["synth", "phi1", "--horizon", "3", "--population", "driver_population_three_types",
     "--objective", "bayes", "--out", "q.json", "--json"],
    ["evaluate", "phi2", "free", "--town", "town01_carla", "--driver", "driver_model", "--json"],
    ["baseline", "phi1_strict", "--town", "town01_carla", "--driver", "driver_model_performance", "--json"],
    ["spec", "check", "phi2", "--town", "town01_carla", "--population", "driver_population_three_types",
     "--json"],
    ["model", "--town", "pentagon", "--driver", "driver_model_performance", "--json"],
    ["population", "show", "driver_population_real", "--json"],
    ["population", "sample", "--driver", "driver_model", "--types", "2", "--seed", "1",
     "--concentration", "50", "--out", "types.json", "--json"],
    ["peer", "storm", "phi1_trust", "--town", "town01_carla", "--driver", "driver_model", "--horizon", "4",
     "--json"],
    ["run", "phi1", "--town", "town01_carla", "--driver", "driver_model", "--policy", "free", "--json"],
    ["run", "phi2", "--population", "driver_population_three_types", "--policy", "free", "--json"],
]


@pytest.mark.parametrize("args", GOOD, ids=lambda args: " ".join(args[:2]))
def test_every_command_takes_packaged_names(capsys, args):
    if args[0] == "peer":
        pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, err = run_cli(capsys, *args)
    assert code in (0, 1), err
    json.loads(out)


BAD = [
    (["synth", "nosuch", "--horizon", "3"], SPECS),
    (["synth", "phi1", "--town", "nosuch", "--horizon", "3"], TOWNS),
    (["synth", "phi1", "--driver", "nosuch", "--horizon", "3"], DRIVER_MODELS),
    (["synth", "phi1", "--population", "nosuch", "--horizon", "3"], POPULATIONS),
    (["evaluate", "nosuch", "free"], SPECS),
    (["evaluate", "phi1", "free", "--town", "nosuch"], TOWNS),
    (["baseline", "nosuch"], SPECS),
    (["baseline", "phi1", "--driver", "nosuch"], DRIVER_MODELS),
    (["spec", "check", "nosuch"], SPECS),
    (["spec", "check", "phi1", "--population", "nosuch"], POPULATIONS),
    (["model", "--town", "nosuch"], TOWNS),
    (["model", "--driver", "nosuch"], DRIVER_MODELS),
    (["net", "build", "--town", "nosuch"], TOWNS),
    (["population", "show", "nosuch"], POPULATIONS),
    (["town", "roads", "nosuch"], TOWNS),
    (["population", "sample", "--driver", "nosuch", "--types", "2", "--seed", "1", "--out", "t.json"],
     DRIVER_MODELS),
    (["run", "nosuch"], SPECS),
    (["run", "phi1", "--town", "nosuch"], TOWNS),
    (["run", "phi1", "--population", "nosuch"], POPULATIONS),
    (["peer", "storm", "nosuch"], SPECS),
    (["peer", "storm", "phi1_trust", "--driver", "nosuch"], DRIVER_MODELS),
]


def _bad_id(value: object) -> str:
    return " ".join(value) if isinstance(value, list) else ""


@pytest.mark.parametrize("args, kind", BAD, ids=_bad_id)
def test_a_bad_name_is_one_line_naming_what_exists(capsys, args, kind):
    if args[0] == "peer":
        pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, err = run_cli(capsys, *args)
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert "nosuch" in err and ", ".join(kind.names()) in err
    assert "specs/phi1.toml" not in err and "participants/data" not in err


@pytest.mark.parametrize(("args", "how"), [
    (["town", "roads", "nosuch"], "town file as TOWN or"),
    (["population", "show", "nosuch"], "driver population file as FILE or"),
    (["run", "phi1", "--town", "nosuch"], "town file with --town or"),
    (["model", "--driver", "nosuch"], "driver model file with --driver or"),
    (["spec", "check", "phi1", "--population", "nosuch"], "driver population file with --population or"),
], ids=_bad_id)
def test_the_hint_names_a_positional_argument_as_one_and_an_option_as_one(capsys, args, how):
    code, _, err = run_cli(capsys, *args)
    assert code == 2 and f"(fix: pass an existing {how} a packaged" in err, err


def test_study_config_takes_packaged_names(outside_the_repository):
    from trustroute.core.errors import InputError
    from trustroute.harness.study.config import load_study_config

    config = outside_the_repository / "s.toml"
    config.write_text('[study]\nparticipants = 2\nseed = 1\nengine = "model"\n'
                      'specs = ["phi1", "phi2_strict"]\nconditions = ["aware", "robust"]\n'
                      'town = "town01_carla"\ndriver_model = "driver_model"\n'
                      'robust_population = "driver_population_three_types"\n'
                      '[drivers]\npopulation = "driver_population_three_types"\n')
    loaded = load_study_config(config)
    assert loaded.town == str(TOWNS.path("town01_carla").resolve())
    assert loaded.driver_model == str(DRIVER_MODELS.path("driver_model").resolve())
    assert loaded.robust_population == str(POPULATIONS.path("driver_population_three_types").resolve())
    config.write_text('[study]\nparticipants = 2\nseed = 1\nspecs = ["phi1"]\nconditions = ["free"]\n'
                      'town = "nosuch"\n')
    with pytest.raises(InputError, match="pentagon, town01_carla"):
        load_study_config(config)


def test_api_and_gym_env_take_packaged_names():
    from trustroute.core.errors import InputError
    from trustroute.harness.simulation.gym_env import TrustRoutingEnv

    assert len(trustroute.load_town("pentagon").junctions) == 12
    assert trustroute.load_driver_model("driver_model_performance").depends_on_performance
    assert trustroute.load_spec("phi1").name == "phi1"
    env = TrustRoutingEnv("phi1", town="town01_carla", driver="driver_model_performance")
    assert env.driver_model.depends_on_performance
    env.close()
    with pytest.raises(InputError, match="driver_model, driver_model_performance"):
        TrustRoutingEnv("phi1", driver="nosuch")
