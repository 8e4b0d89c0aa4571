"""The study config: the minimal form works as written; bad configs give one line and exit 2."""

from __future__ import annotations

import gzip
import os
import shutil
from pathlib import Path

import pytest

from trustroute.core.errors import InputError
from trustroute.harness.cli import main
from trustroute.harness.study.config import load_study_config

REPO = Path(__file__).resolve().parents[2]
MINIMAL = """[study]
participants = 21
seed = 1
engine = "sumo"
specs = ["specs/phi1.toml", "specs/phi2.toml"]
conditions = ["aware", "free"]
"""


def _write(tmp_path: Path, text: str, name: str = "study.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_minimal_config_as_written_from_repo_root(tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)
    config = load_study_config(_write(tmp_path, MINIMAL))
    assert config.participants == 21 and config.seed == 1 and config.engine == "sumo"
    assert config.spec_names == ("phi1", "phi2")
    assert config.conditions == ("aware", "free")
    assert config.fallback_after == 20 and config.population is None
    assert all(Path(s).is_absolute() and Path(s).is_file() for s in config.specs)


def test_minimal_config_from_elsewhere_uses_packaged_specs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = load_study_config(_write(tmp_path, MINIMAL.replace("specs/phi1.toml", "phi1")))
    assert config.spec_names == ("phi1", "phi2")


def test_relative_paths_resolve_against_the_config_folder(tmp_path, monkeypatch):
    folder = tmp_path / "cfg"
    folder.mkdir()
    (folder / "mine.toml").write_text((REPO / "specs" / "phi1.toml").read_text())
    monkeypatch.chdir(tmp_path)
    config = load_study_config(
        _write(folder, MINIMAL.replace('"specs/phi1.toml", "specs/phi2.toml"', '"mine.toml"'))
    )
    assert config.specs == (str((folder / "mine.toml").resolve()),)


def test_default_output_is_in_the_config_folder_not_the_current_directory(tmp_path, monkeypatch):
    """docs/formats/study_config.md: `output` (default studies/<name>) is relative to the config's folder."""
    from trustroute.harness.study.config import study_config_from_dict, study_directory

    folder, elsewhere = tmp_path / "cfg", tmp_path / "elsewhere"
    folder.mkdir()
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    config = load_study_config(_write(folder, MINIMAL.replace("specs/phi1.toml", "phi1"), "mine.toml"))
    assert study_directory(config, None) == (folder / "studies" / "mine").resolve()
    assert study_directory(config, "out") == Path("out")   # --out: as given, from the current directory
    named = load_study_config(_write(folder, MINIMAL.replace("specs/phi1.toml", "phi1") + 'name = "x"\n',
                                     "n.toml"))
    assert study_directory(named, None) == (folder / "studies" / "x").resolve()
    data = {"study": {"participants": 2, "seed": 1, "specs": ["phi1"], "conditions": ["free"]}}
    assert study_directory(study_config_from_dict(data), None) == (elsewhere / "studies" / "study").resolve()


def test_the_largest_documented_seed_runs_a_study(tmp_path, capsys):
    """seed: an integer >= 0 up to 2**63 - 1 (numpy SeedSequence takes it); one more is refused."""
    from tests.cli import run_cli

    text = MINIMAL.replace("specs/phi1.toml", "phi1").replace('"sumo"', '"model"').replace(
        "participants = 21", "participants = 2").replace('["aware", "free"]', '["free"]')
    config = load_study_config(_write(tmp_path, text.replace("seed = 1", f"seed = {2**63 - 1}")))
    assert config.seed == 2**63 - 1
    code, _, err = run_cli(capsys, "study", config.source_path, "--out", str(tmp_path / "out"), "--workers",
                           "1", "--no-report", "--quiet")
    assert code == 0, err
    assert (tmp_path / "out" / "episodes.parquet").is_file()
    with pytest.raises(InputError, match="out of the 64-bit range"):
        load_study_config(_write(tmp_path, text.replace("seed = 1", f"seed = {2**63}"), "over.toml"))


def test_optional_keys_and_population(tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)
    text = (
        MINIMAL + 'fallback_after = false\nhorizon = 12\noutput = "out/x"\n\n[population]\n'
        "concentration = 30.0\nreport_accuracy = 1.0\n"
    )
    config = load_study_config(_write(tmp_path, text))
    assert config.fallback_after is None and config.horizon == 12
    assert config.output == str((tmp_path / "out" / "x").resolve())
    assert config.population == {"concentration": 30.0, "report_accuracy": 1.0}
    assert config.report_accuracy == 1.0


def test_hash_ignores_formatting_but_not_settings(tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)
    a = load_study_config(_write(tmp_path, MINIMAL, "a.toml"))
    b = load_study_config(
        _write(tmp_path, "# comment\n" + MINIMAL.replace(" = ", "=") + 'output = "o"\n', "b.toml")
    )
    c = load_study_config(_write(tmp_path, MINIMAL.replace("seed = 1", "seed = 2"), "c.toml"))
    assert a.content_hash == b.content_hash != c.content_hash


def _project(folder: Path, routes: bytes = b'<routes><vType id="car"/></routes>') -> Path:
    """A study config with its own spec, town, driver model, background routes and policy cache,
    in `folder`, all named relative to the config."""
    folder.mkdir()
    shutil.copy(REPO / "specs" / "phi1.toml", folder / "phi1.toml")
    shutil.copy(REPO / "networks" / "data" / "town01_carla.json", folder / "town.json")
    shutil.copy(REPO / "participants" / "data" / "driver_model.json", folder / "driver.json")
    (folder / "background.rou.xml").write_bytes(routes)
    return _write(folder, MINIMAL.replace('["specs/phi1.toml", "specs/phi2.toml"]', '["phi1.toml"]')
                  + 'town = "town.json"\ndriver_model = "driver.json"\nroutes = ["background.rou.xml"]\n'
                  + 'policy_cache = "cache"\n')


def test_hash_does_not_depend_on_where_the_files_are(tmp_path):
    # the same config and files in another folder (a copied project, another checkout or
    # installation of the packaged files) are the same study: it resumes there
    here = load_study_config(_project(tmp_path / "here"))
    there = load_study_config(_project(tmp_path / "there"))
    assert here.specs != there.specs and here.policy_cache != there.policy_cache
    assert here.content_hash == there.content_hash


def test_hash_covers_the_content_of_every_file_named(tmp_path):
    config = _project(tmp_path / "study")
    before = load_study_config(config).content_hash
    (tmp_path / "study" / "background.rou.xml").write_bytes(b'<routes><vType id="truck"/></routes>')
    assert load_study_config(config).content_hash != before


def test_a_file_named_like_a_condition_does_not_enter_the_hash(tmp_path, monkeypatch):
    config = _write(tmp_path, MINIMAL.replace("specs/phi1.toml", "phi1").replace("specs/phi2.toml", "phi2"))
    monkeypatch.chdir(tmp_path)
    before = load_study_config(config).content_hash
    (tmp_path / "aware").write_text("not a policy")
    assert load_study_config(config).content_hash == before


BAD = {
    "not toml": ("[study\nparticipants = 1", "not valid TOML"),
    "no study table": ("[population]\nconcentration = 1.0\n", "missing [study]"),
    "zero participants": (MINIMAL.replace("participants = 21", "participants = 0"), "study.participants"),
    "bool participants": (MINIMAL.replace("participants = 21", "participants = true"), "study.participants"),
    "missing seed": (MINIMAL.replace("seed = 1\n", ""), "study.seed"),
    "unknown engine": (MINIMAL.replace('"sumo"', '"carla"'), "study.engine"),
    "missing spec file": (MINIMAL.replace("specs/phi1.toml", "specs/nope.toml"), "study.specs"),
    "empty conditions": (MINIMAL.replace('["aware", "free"]', "[]"), "study.conditions"),
    "unknown condition": (MINIMAL.replace('"free"]', '"reckless"]'), "study.conditions"),
    "typo key": (MINIMAL + "particpants = 3\n", "study.particpants"),
    "bad population": (MINIMAL + "[population]\nreport_accuracy = 2\n", "population.report_accuracy"),
    "unknown table": (MINIMAL + "[drivers]\nx = 1\n", "drivers"),
    "bad belief rule": (MINIMAL + 'belief_rule = "magic"\n', "study.belief_rule"),
    "name leaving studies/": (MINIMAL + 'name = "../../x"\n', "study.name"),
    "absolute name": (MINIMAL + 'name = "/tmp/x"\n', "study.name"),
    "NUL in the output": (MINIMAL + 'output = "o\\u0000ut"\n', "study.output"),
    "NUL in the cache": (MINIMAL + 'policy_cache = "po\\u0000l"\n', "study.policy_cache"),
}


@pytest.mark.parametrize("kind", sorted(BAD))
def test_malformed_config_one_line_exit_2(kind, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(REPO)
    text, place = BAD[kind]
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_study_config(path)
    assert place in info.value.one_line()
    with pytest.raises(SystemExit) as exit_info:
        main(["study", str(path), "--out", str(tmp_path / "out"), "--engine", "model"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert err.count("\n") == 1 and err.startswith("error: ") and "fix:" in err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_a_route_file_sumo_cannot_read_is_refused_with_the_config(tmp_path, monkeypatch, capsys):
    """Each route file is parsed once as the config is read (a gzipped one too): one that is not
    XML is one line naming it and `study.routes`, before any study directory is made."""
    monkeypatch.chdir(REPO)
    (tmp_path / "garbage.rou.xml").write_bytes(bytes(range(256)) * 8)
    (tmp_path / "types.rou.xml.gz").write_bytes(gzip.compress(b'<routes><vType id="car"/></routes>'))
    path = _write(tmp_path, MINIMAL + 'routes = ["types.rou.xml.gz", "garbage.rou.xml"]\n')
    with pytest.raises(InputError) as info:
        load_study_config(path)
    assert (info.value.source, info.value.place) == (str(path), "study.routes")
    assert str(tmp_path / "garbage.rou.xml") in info.value.problem
    assert load_study_config(_write(tmp_path, MINIMAL + 'routes = ["types.rou.xml.gz"]\n', "ok.toml")).routes
    with pytest.raises(SystemExit) as exit_info:
        main(["study", str(path), "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2 and "study.routes" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_misspelt_study_key_is_told_the_closest_key_on_an_uncut_line(tmp_path, capsys):
    path = _write(tmp_path, MINIMAL + "sede = 1\n")
    with pytest.raises(SystemExit) as exit_info:
        main(["study", str(path)])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "study.sede" in err
    assert "write seed, the closest key" in err
    assert err.endswith("(a misspelt key would be ignored otherwise))\n")


def test_missing_config_file_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["study", str(tmp_path / "absent.toml")])
    assert exit_info.value.code == 2
    assert "cannot read the study config" in capsys.readouterr().err


def test_example_configs_load(monkeypatch):
    monkeypatch.chdir(REPO)
    examples = sorted((REPO / "harness" / "study" / "examples").glob("*.toml"))
    assert examples
    for path in examples:
        load_study_config(path)
    assert os.path.basename(str(examples[0])).endswith(".toml")


def test_background_vehicles_key():
    from trustroute.core.errors import InputError
    from trustroute.harness.study.config import study_config_from_dict

    base = {"participants": 2, "seed": 1, "specs": ["phi1"], "conditions": ["free"]}
    assert study_config_from_dict({"study": base}).background_vehicles == 0
    assert study_config_from_dict({"study": {**base, "background_vehicles": 12}}).background_vehicles == 12
    for bad in (-1, "many", 1000, True):
        with pytest.raises(InputError, match="background_vehicles"):
            study_config_from_dict({"study": {**base, "background_vehicles": bad}})


def test_the_live_view_key(tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)
    default = load_study_config(_write(tmp_path, MINIMAL))
    driver = load_study_config(_write(tmp_path, MINIMAL + '[live]\nview = "driver"\n', "driver.toml"))
    shown = load_study_config(_write(tmp_path, MINIMAL + '[live]\nview = "map"\n', "map.toml"))
    assert default.live_view == driver.live_view == "driver" and shown.live_view == "map"
    # the default view hashes as a config without [live]; another view is another study
    assert default.content_hash == driver.content_hash != shown.content_hash
    wheel = load_study_config(_write(tmp_path, MINIMAL + '[live]\ndriving = "continuous"\n', "wheel.toml"))
    assert default.live_driving == "assisted" and wheel.live_driving == "continuous"
    assert wheel.content_hash not in (default.content_hash, shown.content_hash)
    with pytest.raises(InputError, match="live.view"):
        load_study_config(_write(tmp_path, MINIMAL + '[live]\nview = "bird"\n', "bad.toml"))
    # the inputs continuous driving allows: all by default (and hashed as without the key); a
    # study may allow fewer, in the canonical order, and only when it drives continuously
    assert wheel.live_inputs == ("wheel", "gamepad", "keyboard") and default.live_inputs == wheel.live_inputs
    every = '[live]\ndriving = "continuous"\ninputs = ["keyboard", "gamepad", "wheel"]\n'
    every_input = load_study_config(_write(tmp_path, MINIMAL + every, "every.toml"))
    assert every_input.content_hash == wheel.content_hash
    only = '[live]\ndriving = "continuous"\ninputs = ["keyboard", "wheel"]\n'
    fewer = load_study_config(_write(tmp_path, MINIMAL + only, "fewer.toml"))
    assert fewer.live_inputs == ("wheel", "keyboard") and fewer.content_hash != wheel.content_hash
    for bad, place in (('driving = "continuous"\ninputs = ["mouse"]', "live.inputs"),
                       ('driving = "continuous"\ninputs = []', "live.inputs"),
                       ('inputs = ["wheel"]', "live.inputs")):   # an assisted study reads no inputs
        with pytest.raises(InputError, match=place):
            load_study_config(_write(tmp_path, MINIMAL + "[live]\n" + bad + "\n", "bad.toml"))
    with pytest.raises(InputError, match="live"):
        load_study_config(_write(tmp_path, MINIMAL + '[live]\nseat = "left"\n', "unknown.toml"))


@pytest.mark.parametrize("engine", ["bogus", 5, "Model"])
def test_an_engine_override_follows_the_config_key_rule(engine, tmp_path, monkeypatch):
    import trustroute

    monkeypatch.chdir(tmp_path)
    config = load_study_config(_write(tmp_path, MINIMAL.replace("specs/phi1.toml", "phi1")))
    assert config.with_overrides(engine="model").engine == "model"
    refused = rf"engine: unknown engine {engine!r} \(fix: use one of 'sumo', 'model', 'live'\)"
    with pytest.raises(InputError, match=refused):
        config.with_overrides(engine=engine)
    with pytest.raises(InputError, match=refused):
        trustroute.run_study(config, tmp_path / "out", engine=engine)
    assert not (tmp_path / "out").exists()


def _numpy_study(np, whole, real) -> dict:
    """A study dict as a script computing its numbers with numpy (or with Python's) writes it."""
    return {"study": {"participants": whole(2), "seed": whole(7), "engine": "model", "specs": ["phi1"],
                      "conditions": ["free"], "horizon": whole(12), "background_vehicles": whole(0)},
            "population": {"concentration": real(50.0), "takeover_spread": real(0.5),
                           "initial_trust": [real(p) for p in (0.5, 0.25, 0.125, 0.0625, 0.0625, 0.0, 0.0)],
                           "report_accuracy": real(0.75)}}


def test_a_study_dict_takes_numpy_numbers_as_the_python_ones(tmp_path):
    """A seed or a participant count a script computed with numpy is the int a TOML file gives, and the
    study writes it as one; a bool is no integer, numpy's neither."""
    import json

    import numpy as np

    import trustroute
    from trustroute.harness.study.config import study_config_from_dict

    computed = study_config_from_dict(_numpy_study(np, np.int64, np.float64))
    written = study_config_from_dict(_numpy_study(np, int, float))
    assert computed == written and computed.content_hash == written.content_hash
    assert type(computed.seed) is type(computed.participants) is type(computed.horizon) is int
    assert computed.population is not None
    assert [type(v) for v in computed.population["initial_trust"]] == [float] * 7
    assert type(computed.population["report_accuracy"]) is float
    assert study_config_from_dict(_numpy_study(np, np.int32, np.float32)) == written
    assert json.loads(json.dumps(computed.to_dict())) == json.loads(json.dumps(written.to_dict()))
    run = trustroute.run_study(_numpy_study(np, np.int64, np.float64), out=tmp_path / "study", workers=1)
    manifest = json.loads((run.study_dir / "manifest.json").read_text())
    assert (manifest["config"]["seed"], manifest["config"]["participants"]) == (7, 2)
    for refused in (True, np.True_):
        data = _numpy_study(np, int, float)
        data["study"]["seed"] = refused
        with pytest.raises(InputError, match="study.seed"):
            study_config_from_dict(data)


def test_a_study_dict_takes_numpy_arrays_strings_and_bools_as_the_python_ones():
    """A list a script holds as a numpy array, a name it took from one (np.str_) and a switch it
    computed (np.bool_) are the list, the string and the bool a TOML file gives."""
    import numpy as np

    from trustroute.harness.study.config import study_config_from_dict

    written = _numpy_study(np, int, float)
    written["study"]["fallback_after"] = False
    computed = _numpy_study(np, int, float)
    computed["study"].update(engine=np.str_("model"), specs=np.array(["phi1"]), conditions=[np.str_("free")],
                             fallback_after=np.bool_(False))
    computed["population"]["initial_trust"] = np.array(written["population"]["initial_trust"])
    checked, expected = study_config_from_dict(computed), study_config_from_dict(written)
    assert checked == expected and checked.content_hash == expected.content_hash
    assert checked.population is not None
    assert [type(v) for v in checked.population["initial_trust"]] == [float] * 7
    computed["study"]["seed"] = np.bool_(True)   # a bool is no integer, numpy's neither
    with pytest.raises(InputError, match="study.seed"):
        study_config_from_dict(computed)


def test_a_study_dict_takes_paths_and_tuples_as_the_strings_and_lists(tmp_path):
    """A file a script names with pathlib and a list it writes as a tuple are the string and the list
    a TOML file gives: the same config, the same hash."""
    import numpy as np

    from trustroute.harness.study.config import study_config_from_dict
    from trustroute.participants.driver_population import POPULATIONS

    population = POPULATIONS.resolve("driver_population_three_types")
    written = _numpy_study(np, int, float)
    written["drivers"] = {"population": str(population)}
    computed = _numpy_study(np, int, float)
    computed["study"].update(specs=("phi1",), conditions=("free",))
    computed["study"]["policy_cache"] = tmp_path / "cache"
    written["study"]["policy_cache"] = str(tmp_path / "cache")
    computed["drivers"] = {"population": population}
    computed["population"]["initial_trust"] = tuple(written["population"]["initial_trust"])
    checked, expected = study_config_from_dict(computed), study_config_from_dict(written)
    assert checked == expected and checked.content_hash == expected.content_hash


def test_a_missing_file_names_each_folder_searched_once(tmp_path, monkeypatch):
    """The config's folder and the current directory are named once when they are one folder, and
    not at all for an absolute path, which is looked for nowhere else."""
    import re

    monkeypatch.chdir(tmp_path)
    folder = re.escape(str(tmp_path.resolve()))
    config = _write(tmp_path, MINIMAL + 'town = "drtx.json"\n')
    with pytest.raises(InputError, match=rf"town file 'drtx.json' not found \(looked in {folder}\) \(fix"):
        load_study_config(config)
    absolute = tmp_path / "gone.json"
    config.write_text(MINIMAL + f'town = "{absolute}"\n')
    with pytest.raises(InputError, match=rf"town file '{re.escape(str(absolute))}' not found \(fix: "):
        load_study_config(config)
    config.write_text(MINIMAL.replace('"specs/phi2.toml"', '"nope.toml"'))
    with pytest.raises(InputError, match=rf"spec 'nope.toml' not found \(looked in {folder} and the packaged "
                                         r"specs\)"):
        load_study_config(config)
