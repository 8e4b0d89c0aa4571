"""The bad-input matrix: malformed inputs of every kind through the CLI (docs/input_files.md).

Every case must give exit code 2, at most 3 lines on stderr, no traceback, finish within 20 s,
and write nothing: the folder holding the case (its input files and the command's --out, dot,
policy-cache or net-cache paths) has exactly the same files before and after. Kinds: town, driver
model, spec, study config, policy file (JSON + .npz), command-line options and outputs, outputs
that are an input of their command (a net, a study), and the tables of a finished study (analyze,
fit, export).
Runs in-process (tests/cli.py); a SIGALRM turns a hang (a FIFO read, a runaway loop) into a failure.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tests.cli import run_cli
from tests.harness.helpers import run_study
from tests.networks.sumo_nets import WHEEL_NODES, WHEEL_ROADS, build_plain_net
from tests.study_tables import Edit, duplicate_row, set_values, study_copy
from trustroute.core.dataset import EPISODES_FILE, ROADS_FILE
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.networks.town import DEFAULT_TOWN_PATH
from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH
from trustroute.policies.routing.files import VERSION as POLICY_VERSION
from trustroute.policies.synthesis.settings import SynthesisSettings

SPECS = PACKAGED_SPECS
PHI1 = SPECS / "phi1.toml"
CASE_SECONDS = 20
BIG = 20 * 1024 * 1024  # over the 16 MiB cap of text inputs (a sparse file: cheap to make)


@dataclass(frozen=True)
class Case:
    kind: str
    name: str
    make: Callable[[Path], Path]  # writes the bad input under the folder, returns its path
    command: Callable[[Path, Path], list[str]]  # (bad input, folder) -> CLI arguments


# -- helpers that write bad files ------------------------------------------------------------------


def text(name: str, content: str | bytes) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        path = folder / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        return path

    return make


def fifo(name: str) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        path = folder / name
        os.mkfifo(path)
        return path

    return make


def directory(name: str) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        path = folder / name
        path.mkdir()
        return path

    return make


def sparse(name: str, size: int = BIG) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        path = folder / name
        with path.open("wb") as handle:
            handle.truncate(size)
        return path

    return make


def json_edit(name: str, base: Path, edit: Callable[[dict], object]) -> Callable[[Path], Path]:
    def make(folder: Path) -> Path:
        data = json.loads(base.read_text())
        result = edit(data)
        path = folder / name
        path.write_text(result if isinstance(result, str) else json.dumps(data))
        return path

    return make


def town_edit(edit):
    return json_edit("town.json", DEFAULT_TOWN_PATH, edit)


def driver_edit(edit):
    return json_edit("driver.json", DEFAULT_DRIVER_MODEL_PATH, edit)


def replace_in_town(old: str, new: str) -> Callable[[dict], str]:
    def edit(data: dict) -> str:
        out = json.dumps(data)
        assert old in out
        return out.replace(old, new, 1)

    return edit


def with_key(key: str, value: object) -> Callable[[dict], None]:
    def edit(data: dict) -> None:
        data[key] = value

    return edit


def nested(depth: int) -> str:
    return "[" * depth + "]" * depth


# -- town ------------------------------------------------------------------------------------------

TOWN_TEXT = DEFAULT_TOWN_PATH.read_text()


def town_command(path: Path, folder: Path) -> list[str]:
    return ["net", "build", "--town", str(path), "--out", str(folder / "nets")]


def _all_junctions_at_one_point(data: dict) -> None:
    for name in data["junctions"]:
        data["junctions"][name] = [5.0, 5.0]


def _huge_coordinates(data: dict) -> None:
    for k, name in enumerate(sorted(data["junctions"])):
        data["junctions"][name] = [1e308 if k % 2 else -1e308, 1e308]


def _deep_town(data: dict) -> None:
    data["junctions"]["A"] = json.loads(nested(200))


TOWN_CASES = [
    ("non_utf8_byte", text("town.json", TOWN_TEXT.encode().replace(b'"A"', b'"\xff"', 1))),
    ("huge_integer", town_edit(replace_in_town("[", "[" + "9" * 5000 + ", "))),
    ("integer_over_int64", town_edit(replace_in_town("[", "[123456789012345678901, "))),
    ("float_overflow_1e400", town_edit(replace_in_town("[", "[1e400, "))),
    ("nan_literal", town_edit(replace_in_town("[", "[NaN, "))),
    ("deeply_nested", town_edit(replace_in_town('"roads": ', '"roads": ' + nested(100000) + ", \"x\": "))),
    ("deep_but_parsed_value", town_edit(_deep_town)),
    ("fifo", fifo("town.json")),
    ("directory", directory("town.json")),
    ("over_size_cap", sparse("town.json")),
    ("empty_file", text("town.json", "")),
    ("truncated", text("town.json", TOWN_TEXT[: len(TOWN_TEXT) // 2])),
    ("duplicate_key", text("town.json", TOWN_TEXT.replace('"junctions": {', '"junctions": {"A": [1, 2], ',
                                                          1))),
    ("unknown_key", town_edit(with_key("junctoins", {}))),
    ("all_junctions_at_one_point", town_edit(_all_junctions_at_one_point)),
    ("coordinates_1e308", town_edit(_huge_coordinates)),
    ("junction_name_with_newline", town_edit(replace_in_town('"A"', '"A\\nB"'))),
    ("not_an_object", text("town.json", "[1, 2, 3]")),
]

# -- driver model ------------------------------------------------------------------------------------

DRIVER_TEXT = DEFAULT_DRIVER_MODEL_PATH.read_text()


def driver_command(path: Path, folder: Path) -> list[str]:
    return ["synth", str(PHI1), "--driver", str(path), "--horizon", "3", "--out", str(folder / "p.json")]


def five_trust_levels(data: dict) -> None:
    """A consistent 5-level model (every table resized): the 7-coefficient spec must refuse it."""
    n = 5
    data["trust_levels"] = list(range(1, n + 1))
    data["initial_belief"] = [1 / n] * n
    for incident in data["incident_types"]:
        data["takeover_probability"][incident] = data["takeover_probability"][incident][:n]
        for action in ("takeover", "standstill"):
            data["trust_transition"][incident][action] = np.eye(n).tolist()


def _levels(count: int) -> Callable[[dict], None]:
    def edit(data: dict) -> None:
        data["trust_levels"] = list(range(1, count + 1))

    return edit


def _unknown_transition_key(data: dict) -> None:
    first = data["incident_types"][0]
    data["trust_transition"][first]["takeovr"] = data["trust_transition"][first]["takeover"]


def _row_not_stochastic(data: dict) -> None:
    first = data["incident_types"][0]
    data["trust_transition"][first]["takeover"][0][0] += 0.5


DRIVER_CASES = [
    ("non_utf8_byte", text("driver.json", DRIVER_TEXT.encode().replace(b"trust_levels", b"trust_\xfel", 1))),
    ("huge_integer", driver_edit(lambda d: json.dumps(d).replace("[1, 2", "[" + "1" * 5000 + ", 2", 1))),
    ("integer_over_int64", driver_edit(lambda d: json.dumps(d).replace("[1, 2", "[1234567890123456789, 2",
                                                                        1))),
    ("float_overflow_1e400", driver_edit(lambda d: json.dumps(d).replace("[0.", "[1e400, 0.", 1))),
    ("nan_literal", driver_edit(lambda d: json.dumps(d).replace("[0.", "[NaN, 0.", 1))),
    ("deeply_nested", text("driver.json", '{"source": ' + nested(50000) + "}")),
    ("fifo", fifo("driver.json")),
    ("directory", directory("driver.json")),
    ("over_size_cap", sparse("driver.json")),
    ("empty_file", text("driver.json", "")),
    ("truncated", text("driver.json", DRIVER_TEXT[:-40])),
    ("duplicate_key", text("driver.json", DRIVER_TEXT.replace("{", '{"source": "x", ', 1))),
    ("unknown_key", driver_edit(with_key("takeover_probabilty", {}))),
    ("unknown_nested_key", driver_edit(_unknown_transition_key)),
    ("five_trust_levels_vs_seven_level_spec", driver_edit(five_trust_levels)),
    ("too_many_trust_levels", driver_edit(_levels(10_000))),
    ("row_not_stochastic", driver_edit(_row_not_stochastic)),
]

# -- spec --------------------------------------------------------------------------------------------

SPEC_TEXT = PHI1.read_text()


def spec_check_command(path: Path, folder: Path) -> list[str]:
    return ["spec", "check", str(path), "--dot", str(folder / "dfa.dot")]


def spec_cache_command(path: Path, folder: Path) -> list[str]:
    """`evaluate SPEC aware` synthesizes into the cache: the spec name must not escape it."""
    return ["evaluate", str(path), "aware", "--cache-dir", str(folder / "cache")]


def spec_with(old: str, new: str) -> Callable[[Path], Path]:
    assert old in SPEC_TEXT
    return text("spec.toml", SPEC_TEXT.replace(old, new, 1))


BIG_FORMULA_ATOMS = 14
BIG_FORMULA = (
    "name = \"big\"\nstart = \"E-A\"\nformula = \""
    + " & ".join(f"F a{i}" for i in range(BIG_FORMULA_ATOMS))
    + "\"\n[states]\n"
    + "\n".join(f'a{i} = ["A-B"]' for i in range(BIG_FORMULA_ATOMS))
    + "\n"
)

SPEC_CASES = [
    ("non_utf8_byte", text("spec.toml", SPEC_TEXT.encode().replace(b"phi1", b"phi\xff", 1)),
     spec_check_command),
    ("huge_integer", spec_with("offset = 1", "offset = " + "9" * 5000), spec_check_command),
    ("integer_over_int64", spec_with("offset = 1", "offset = 12345678901234567890"), spec_check_command),
    ("deeply_nested_toml", spec_with("offset = 1", "offset = " + nested(50000)), spec_check_command),
    ("formula_with_50k_parentheses", spec_with('formula = "', 'formula = "' + "(" * 50000 + "v1" + ")" * 50000
                                               + ' | '), spec_check_command),
    ("formula_nested_5000_deep", spec_with('formula = "', 'formula = "' + "(" * 5000 + "v1" + ")" * 5000
                                           + ' | '), spec_check_command),
    ("nan_offset", spec_with("offset = 1", "offset = nan"), spec_check_command),
    ("inf_offset", spec_with("offset = 1", "offset = inf"), spec_check_command),
    ("fifo", fifo("spec.toml"), spec_check_command),
    ("directory", directory("spec.toml"), spec_check_command),
    ("over_size_cap", sparse("spec.toml"), spec_check_command),
    ("empty_file", text("spec.toml", ""), spec_check_command),
    ("duplicate_key", spec_with('start = "E-A"', 'start = "E-A"\nstart = "E-A"'), spec_check_command),
    ("unknown_key", spec_with('start = "E-A"', 'start = "E-A"\nstrat = "E-A"'), spec_check_command),
    ("dfa_too_large", text("spec.toml", BIG_FORMULA), spec_check_command),
    ("name_with_nul", spec_with('name = "phi1"', 'name = "phi\\u0000one"'), spec_cache_command),
    ("name_with_parent_dirs", spec_with('name = "phi1"', 'name = "../../../escaped"'), spec_cache_command),
    ("name_of_300_chars", spec_with('name = "phi1"', f'name = "{"p" * 300}"'), spec_cache_command),
    # Any number of trust levels is a valid spec; against the 7-level default driver model it is a
    # mismatch, which every command that reads the spec finds (the one spec loader).
    ("five_coefficients", spec_with("coeffs = [1, 0, 0, 0, 0, 0, 0]", "coeffs = [1, 0, 0, 0, 0]"),
     spec_cache_command),
    ("five_coefficients_spec_check", spec_with("coeffs = [1, 0, 0, 0, 0, 0, 0]", "coeffs = [1, 0, 0, 0, 0]"),
     spec_check_command),
]

# -- study config ---------------------------------------------------------------------------------------

STUDY_TEXT = """[study]
participants = 2
seed = 1
engine = "model"
specs = ["phi1"]
conditions = ["free"]
"""


def study_command(path: Path, folder: Path) -> list[str]:
    return ["study", str(path), "--out", str(folder / "out"), "--workers", "1", "--no-report"]


def study_with(old: str, new: str) -> Callable[[Path], Path]:
    assert old in STUDY_TEXT
    return text("study.toml", STUDY_TEXT.replace(old, new, 1))


def _study_with_bad_spec(folder: Path) -> Path:
    (folder / "bad.toml").write_text(SPEC_TEXT.replace('name = "phi1"', 'name = "../x"'))
    return study_with('specs = ["phi1"]', 'specs = ["bad.toml"]')(folder)


def _study_with_bad_town(folder: Path) -> Path:
    (folder / "town.json").write_text(TOWN_TEXT.replace('"junctions": {', '"junctions": {"A": [1, 2], ', 1))
    return study_with("seed = 1", 'seed = 1\ntown = "town.json"')(folder)


def _study_with_garbage_routes(folder: Path) -> Path:
    (folder / "garbage.rou.xml").write_bytes(bytes(range(256)) * 8)
    return study_with('engine = "model"', 'engine = "sumo"\nroutes = ["garbage.rou.xml"]')(folder)


STUDY_CASES = [
    ("non_utf8_byte", text("study.toml", STUDY_TEXT.encode().replace(b"seed", b"se\xc3\x28d", 1))),
    ("participants_2_pow_63_minus_1", study_with("participants = 2", "participants = 9223372036854775807")),
    ("participants_over_limit", study_with("participants = 2", "participants = 100000000")),
    ("huge_integer", study_with("seed = 1", "seed = " + "7" * 5000)),
    ("deeply_nested", study_with("seed = 1", "seed = 1\nname = " + nested(50000))),
    ("fifo", fifo("study.toml")),
    ("directory", directory("study.toml")),
    ("over_size_cap", sparse("study.toml")),
    ("empty_file", text("study.toml", "")),
    ("duplicate_key", study_with("seed = 1", "seed = 1\nseed = 2")),
    ("unknown_key", study_with("seed = 1", "seed = 1\nsede = 2")),
    ("unknown_engine", study_with('engine = "model"', 'engine = "carla"')),
    ("nan_in_population", study_with('conditions = ["free"]', 'conditions = ["free"]\n[population]\n'
                                      "takeover_spread = nan")),
    ("negative_seed", study_with("seed = 1", "seed = -1")),
    ("horizon_zero", study_with("seed = 1", "seed = 1\nhorizon = 0")),
    ("missing_spec_file", study_with('specs = ["phi1"]', 'specs = ["nowhere.toml"]')),
    ("policy_file_that_is_a_directory", study_with('conditions = ["free"]', 'conditions = ["."]')),
    ("bad_spec_name_inside", _study_with_bad_spec),
    ("name_with_parent_dirs", study_with("seed = 1", 'seed = 1\nname = "../../escaped"')),
    ("bad_town_inside", _study_with_bad_town),
    ("routes_of_random_bytes", _study_with_garbage_routes),
]

# -- policy file ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def good_policy(tmp_path_factory) -> Path:
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.routing.files import save_policy
    from trustroute.policies.synthesis.belief_synthesis import synthesize

    town, driver = load_town(), load_driver_model()
    spec = load_spec(PHI1, town)
    result = synthesize(build_pomdp(town, driver), spec,
                        SynthesisSettings(tau=1e-3, time_limit=30, horizon=6))
    assert result.policy.table.rows > 0
    return save_policy(result, tmp_path_factory.mktemp("policy") / "good.json", town, driver, spec)


def policy_command(path: Path, folder: Path) -> list[str]:
    return ["evaluate", str(PHI1), str(path), "--max-junctions", "8"]


def _copy_policy(good: Path, folder: Path, document: dict | None = None, arrays: dict | None = None,
                 npz_bytes: bytes | None = None, json_text: str | None = None) -> Path:
    doc = json.loads(good.read_text())
    if npz_bytes is None:
        with np.load(good.with_suffix(".npz")) as data:
            table = {k: data[k] for k in data.files}
        table.update(arrays or {})
        buffer = io.BytesIO()
        np.savez(buffer, **table)
        npz_bytes = buffer.getvalue()
    doc.update(document or {})
    doc["arrays"] = doc.get("arrays") if document and "arrays" in document else "bad.npz"
    doc["arrays_sha256"] = hashlib.sha256(npz_bytes).hexdigest()
    if doc["arrays"] == "bad.npz":
        (folder / "bad.npz").write_bytes(npz_bytes)
    path = folder / "bad.json"
    path.write_text(json_text if json_text is not None else json.dumps(doc))
    return path


def policy_case(**kwargs) -> Callable[[Path, Path], Path]:
    return lambda good, folder: _copy_policy(good, folder, **kwargs)


def _damaged_npz(good: Path, folder: Path) -> Path:
    data = bytearray(good.with_suffix(".npz").read_bytes())
    middle = len(data) // 2
    data[middle : middle + 16] = bytes(b ^ 0x5A for b in data[middle : middle + 16])
    return _copy_policy(good, folder, npz_bytes=bytes(data))


def _first_action_out_of_range(good: Path) -> dict:
    with np.load(good.with_suffix(".npz")) as data:
        action = data["action"].copy()
    action[0] = 99
    return {"action": action}


def _policy_json_text(transform: Callable[[str], str]) -> Callable[[Path, Path], Path]:
    def make(good: Path, folder: Path) -> Path:
        path = _copy_policy(good, folder)
        path.write_bytes(transform(path.read_text()).encode("latin-1"))  # latin-1: é is one non-UTF-8 byte
        return path

    return make


def _policy_fifo_npz(good: Path, folder: Path) -> Path:
    path = _copy_policy(good, folder, document={"arrays": "fifo.npz"})
    os.mkfifo(folder / "fifo.npz")
    return path


def _policy_object_array(good: Path, folder: Path) -> Path:
    return _copy_policy(good, folder, arrays={"action": np.array([{"a": 1}], dtype=object)})


POLICY_CASES = [
    ("horizon_as_text", policy_case(document={"horizon": "twenty"})),
    ("non_utf8_json", _policy_json_text(lambda t: t.replace('"aware"', '"aw\xe9re"'))),
    ("huge_integer", _policy_json_text(lambda t: t.replace(f'"version": {POLICY_VERSION}',
                                                           '"version": ' + "3" * 5000))),
    ("deeply_nested", _policy_json_text(lambda t: t.replace('"name": "aware"', '"name": ' + nested(50000)))),
    ("duplicate_key", _policy_json_text(lambda t: t.replace("{", '{"name": "x", ', 1))),
    ("unknown_key", policy_case(document={"horizn": 4})),
    ("bound_out_of_range", policy_case(document={"lower": 2.0})),
    ("nan_bound", _policy_json_text(lambda t: t.replace('"lower": ', '"lower": NaN, "x_": ', 1))),
    ("fifo_json", lambda good, folder: fifo("bad.json")(folder)),
    ("directory_json", lambda good, folder: directory("bad.json")(folder)),
    ("damaged_npz_hash_updated", _damaged_npz),
    ("empty_npz_hash_updated", policy_case(npz_bytes=b"")),
    ("npz_missing_array", lambda good, folder: _copy_policy(good, folder, npz_bytes=_npz_without(good, "q"))),
    ("action_out_of_range", lambda good, folder: _copy_policy(good, folder,
                                                              arrays=_first_action_out_of_range(good))),
    ("road_out_of_range", lambda good, folder: _copy_policy(good, folder,
                                                            arrays=_first_road_out_of_range(good))),
    ("nan_belief", lambda good, folder: _copy_policy(good, folder, arrays=_nan_belief(good))),
    ("object_array_needs_pickle", _policy_object_array),
    ("arrays_outside_folder", policy_case(document={"arrays": "../elsewhere.npz"})),
    ("fifo_npz", _policy_fifo_npz),
]


def _npz_without(good: Path, name: str) -> bytes:
    with np.load(good.with_suffix(".npz")) as data:
        table = {k: data[k] for k in data.files if k != name}
    buffer = io.BytesIO()
    np.savez(buffer, **table)
    return buffer.getvalue()


def _first_road_out_of_range(good: Path) -> dict:
    with np.load(good.with_suffix(".npz")) as data:
        x = data["x"].copy()
    x[0] = 10_000
    return {"x": x}


def _nan_belief(good: Path) -> dict:
    with np.load(good.with_suffix(".npz")) as data:
        beliefs = data["beliefs"].copy()
    beliefs[0, 0] = np.nan
    return {"beliefs": beliefs}


# -- a finished study's tables ----------------------------------------------------------------------


def table_case(file_name: str, edit: Edit) -> Callable[[Path, Path], Path]:
    """A copy of the finished `model_study` in the case's folder with one table edited."""
    return lambda study, folder: study_copy(study, folder / "study", file_name, edit)


def table_command(*args: str) -> Callable[[Path, Path], list[str]]:
    return lambda study, folder: [a.replace("{study}", str(study)).replace("{folder}", str(folder))
                                  for a in args]


ANALYZE = table_command("analyze", "{study}", "--json")
FIT = table_command("fit", "{study}", "--out", "{folder}/fitted.json")
EXPORT = table_command("export", "{study}", "--out", "{folder}/package")
TABLE_CASES = [
    ("road_not_in_the_town", table_case(ROADS_FILE, set_values("directed_road", "ZZ-YY")), ANALYZE),
    ("incident_not_in_the_driver_model", table_case(ROADS_FILE, set_values("incident", "meteor")), ANALYZE),
    ("spec_not_in_the_study", table_case(EPISODES_FILE, set_values("spec", "phi9")), ANALYZE),
    ("reported_trust_99", table_case(ROADS_FILE, set_values("reported_trust", 99, [3])), FIT),
    ("true_trust_negative", table_case(ROADS_FILE, set_values("trust_after", -3, [3])), EXPORT),
    ("nan_belief", table_case(ROADS_FILE, set_values("belief_after", [float("nan")] * 7, [3])), ANALYZE),
    ("duplicated_episode", table_case(EPISODES_FILE, duplicate_row(0)), ANALYZE),
    ("roads_of_no_episode", table_case(ROADS_FILE, set_values("episode_id", "p00000-phi1-none", [3])),
     EXPORT),
]

# -- command-line options and outputs -----------------------------------------------------------------


def options(*args: str) -> Callable[[Path, Path], list[str]]:
    return lambda path, folder: [a.replace("{folder}", str(folder)) for a in args]


def no_file(folder: Path) -> Path:
    return folder


OPTION_CASES = [
    ("tau_nan", options("synth", str(PHI1), "--tau", "nan", "--out", "{folder}/p.json")),
    ("tau_inf", options("synth", str(PHI1), "--tau", "inf", "--out", "{folder}/p.json")),
    ("tau_negative", options("synth", str(PHI1), "--tau", "-1", "--out", "{folder}/p.json")),
    ("time_limit_nan", options("synth", str(PHI1), "--time-limit", "nan", "--out", "{folder}/p.json")),
    ("work_limit_zero", options("synth", str(PHI1), "--work-limit", "0", "--out", "{folder}/p.json")),
    ("work_limit_negative", options("synth", str(PHI1), "--work-limit", "-5", "--out", "{folder}/p.json")),
    ("work_limit_fraction", options("synth", str(PHI1), "--work-limit", "2.5", "--out", "{folder}/p.json")),
    ("work_limit_not_a_number", options("synth", str(PHI1), "--work-limit", "lots", "--out",
                                        "{folder}/p.json")),
    ("horizon_huge", options("synth", str(PHI1), "--horizon", "1000000000", "--out", "{folder}/p.json")),
    ("synth_out_is_a_directory", options("synth", str(PHI1), "--horizon", "3", "--out", "{folder}")),
    ("synth_out_under_a_file", options("synth", str(PHI1), "--horizon", "3", "--out",
                                       "{folder}/marker/p.json")),
    ("run_rrd_is_a_directory", options("run", "--spec", str(PHI1), "--rrd", "{folder}")),
    ("run_out_is_a_file", options("run", "--spec", str(PHI1), "--out", "{folder}/marker")),
    ("run_seed_too_large", options("run", "--spec", str(PHI1), "--seed", str(2**40))),
    ("spec_dot_is_a_directory", options("spec", "check", str(PHI1), "--dot", "{folder}")),
    ("study_scheduler_not_an_address", options("study", "{folder}/study.toml", "--out", "{folder}/out",
                                               "--scheduler", "not an address")),
    ("study_workers_zero", options("study", "{folder}/study.toml", "--out", "{folder}/out", "--workers",
                                   "0")),
    ("study_out_is_a_file", options("study", "{folder}/study.toml", "--out", "{folder}/marker")),
    ("evaluate_max_junctions_negative", options("evaluate", str(PHI1), "free", "--max-junctions", "-5")),
    # an output that is an input of the command: refused before the input is overwritten
    ("synth_out_is_the_spec", options("synth", "{folder}/spec.toml", "--horizon", "3", "--out",
                                      "{folder}/spec.toml")),
    ("synth_out_is_a_link_to_the_spec", options("synth", "{folder}/spec.toml", "--horizon", "3", "--out",
                                                "{folder}/link.json")),
    ("synth_arrays_are_the_driver", options("synth", str(PHI1), "--driver", "{folder}/model.npz", "--horizon",
                                            "3", "--out", "{folder}/model.json")),
    ("population_out_is_the_driver", options("population", "sample", "--types", "2", "--seed", "1",
                                             "--driver", "{folder}/driver.json", "--concentration", "50",
                                             "--out", "{folder}/driver.json")),
    ("spec_dot_is_the_spec", options("spec", "check", "{folder}/spec.toml", "--dot", "{folder}/spec.toml")),
    ("run_rrd_is_the_spec", options("run", "{folder}/spec.toml", "--rrd", "{folder}/spec.toml")),
    ("plan_preregistration_is_the_config", options("plan", "{folder}/study.toml", "--participants", "2",
                                                   "--simulations", "10", "--out", "{folder}/plan",
                                                   "--preregistration", "{folder}/study.toml")),
    ("plan_participants_over_a_study", options("plan", "{folder}/study.toml", "--participants",
                                               "99999999999")),
]


def _option_inputs(folder: Path) -> Path:
    (folder / "study.toml").write_text(STUDY_TEXT)
    (folder / "marker").write_text("a file, not a folder\n")
    (folder / "spec.toml").write_text(SPEC_TEXT)
    (folder / "link.json").symlink_to("spec.toml")
    (folder / "driver.json").write_text(DRIVER_TEXT)
    (folder / "model.npz").write_text(DRIVER_TEXT)   # a driver model named as the policy's arrays would be
    return folder


def _small_study(folder: Path) -> Path:
    run_study(folder / "study.toml", STUDY_TEXT, folder / "study")
    return folder / "study"


OUTPUT_CASES = [
    ("town_import_out_is_the_net", lambda folder: build_plain_net(folder, "wheel", WHEEL_NODES, WHEEL_ROADS),
     lambda net, folder: ["town", "import", str(net), "--out", str(net), "--incident-seed", "1"]),
    ("fit_out_is_in_the_study", _small_study,
     lambda study, folder: ["fit", str(study), "--out", str(study / "manifest.json")]),
]


CASES: list[Case] = (
    [Case("town", n, make, town_command) for n, make in TOWN_CASES]
    + [Case("driver", n, make, driver_command) for n, make in DRIVER_CASES]
    + [Case("spec", n, make, command) for n, make, command in SPEC_CASES]
    + [Case("study", n, make, study_command) for n, make in STUDY_CASES]
    + [Case("policy", n, make, policy_command) for n, make in POLICY_CASES]
    + [Case("options", n, _option_inputs, command) for n, command in OPTION_CASES]
    + [Case("outputs", n, make, command) for n, make, command in OUTPUT_CASES]
    + [Case("table", n, make, command) for n, make, command in TABLE_CASES]
)


def _snapshot(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): (p.lstat().st_size if p.is_file() else -1) for p in root.rglob("*")}


class Hang(Exception):
    pass


def _alarm(signum, frame):  # noqa: ARG001
    raise Hang(f"no answer within {CASE_SECONDS} s")


@pytest.mark.parametrize("case", CASES, ids=[f"{c.kind}-{c.name}" for c in CASES])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(case, tmp_path, capsys, monkeypatch, request):
    import trustroute.policies.logic.dfa as dfa

    # The DFA limit is what `dfa_too_large` exercises, not the time to reach the real limit.
    monkeypatch.setattr(dfa, "MAX_STATES", 2_000)
    folder = tmp_path / "case"
    folder.mkdir()
    if case.kind in ("policy", "table"):
        good = request.getfixturevalue("good_policy" if case.kind == "policy" else "model_study")
        path = case.make(good, folder)
    else:
        path = case.make(folder)
    before = _snapshot(folder)
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_SECONDS)
    started = time.monotonic()
    try:
        code, out, err = run_cli(capsys, *case.command(path, folder))
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    seconds = time.monotonic() - started
    lines = err.strip().splitlines()
    assert code == 2, f"exit {code}; stdout {out[-300:]!r}; stderr {err[-600:]!r}"
    assert 1 <= len(lines) <= 3, err
    assert "Traceback" not in err and "Traceback" not in out
    assert lines[-1].startswith("error: "), err
    assert seconds < CASE_SECONDS
    assert _snapshot(folder) == before, "the command wrote or removed files"
    assert not list(tmp_path.parent.glob("escaped*")), "a spec name wrote outside the cache"
