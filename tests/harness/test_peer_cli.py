"""`trustroute peer storm`: Storm's bounds beside ours, and the one-line error without stormpy."""

from __future__ import annotations

import json
import time

import pytest

from tests.cli import run_cli


def test_without_stormpy_the_command_says_how_to_install_it(capsys, monkeypatch):
    import trustroute.policies.peer.storm as storm

    monkeypatch.setattr(storm, "storm_available", lambda: False)
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", "4")
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "stormpy" in err and "trustroute[peer]" in err


def test_belief_atoms_are_a_one_line_error(capsys):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, _, err = run_cli(capsys, "peer", "storm", "specs/phi1.toml", "--horizon", "4")
    assert code == 2 and err.count("\n") == 1 and "hightrust" in err


def test_json_reports_both_sides(capsys):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, _ = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", "6",
                           "--time-limit", "1", "--json")
    assert code == 0
    result = json.loads(out)
    storm, ours = result["storm"], result["ours"]
    assert result["overlap"] and ours["gap"] <= 1e-11
    assert storm["lower"] - 1e-6 <= ours["lower"] <= storm["upper"] + 1e-6
    assert storm["lower_seconds"] >= 0 and ours["seconds"] >= 0


@pytest.mark.parametrize("horizon", ["1", "5"])
def test_no_route_within_the_horizon_is_an_answer_not_an_error(capsys, horizon):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", horizon,
                             "--time-limit", "1", "--json")
    assert code == 0 and "Traceback" not in err
    result = json.loads(out)
    assert (result["storm"]["lower"], result["storm"]["upper"]) == (0.0, 0.0)
    assert "no reachable state" in result["storm"]["note"]
    assert result["ours"]["upper"] <= 1e-11 and result["overlap"]
    code, out, _ = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", horizon,
                           "--time-limit", "1")
    assert code == 0 and "note: no reachable state" in out


BAD_PEER_INPUTS = [
    ["missing.toml", "--horizon", "3"],
    ["README.md", "--horizon", "3"],
    ["specs/phi2.toml", "--horizon", "3"],
    ["specs/phi1_strict.toml"],
    ["specs/phi1_trust.toml", "--town", "missing.json", "--horizon", "3"],
    ["specs/phi1_trust.toml", "--driver", "missing.json", "--horizon", "3"],
    ["specs/phi1_trust.toml", "--driver", "participants/data/driver_population_three_types.json",
     "--horizon", "3"],
    ["specs/phi1_trust.toml", "--horizon", "-1"],
]


@pytest.mark.parametrize("args", BAD_PEER_INPUTS)
def test_every_input_storm_cannot_take_is_one_line_and_exit_2(capsys, args):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, err = run_cli(capsys, "peer", "storm", *args, "--time-limit", "1")
    assert code == 2 and out == "" and "Traceback" not in err
    assert err.strip().count("\n") == 0 or err.startswith("Usage:"), err


def test_a_storm_failure_is_one_line_and_exit_2(capsys, monkeypatch):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    import stormpy.pomdp

    def refuse(*_args, **_kwargs):
        raise RuntimeError("InvalidPropertyException: a product Storm cannot take")

    monkeypatch.setattr(stormpy.pomdp, "verify_with_belief_unfolding", refuse)
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--horizon", "6",
                             "--time-limit", "1")
    assert code == 2 and out == "" and err.count("\n") == 1 and "Storm cannot take" in err


@pytest.mark.parametrize("command", ["storm", "paynt"])
def test_our_time_limit_stops_our_search_with_bounds_that_hold_its_full_ones(capsys, command):
    """--our-time-limit on a problem our search takes longer for (within 8 junctions, some 16,000
    nodes, 0.06 s alone): our side stops by it, with bounds holding those of the run without it,
    and says so in the JSON ("stopped_by") and the text. A limit of 1e-6 s is past before the
    search checks it first (the relaxation it values leaves by takes a millisecond to build), so
    where it stops does not hang on the machine's speed or load."""
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    if command == "paynt":
        pytest.importorskip("paynt", reason="needs the optional extra: pip install -e '.[peer]'")
    args = ("peer", command, "specs/phi1_trust.toml", "--horizon", "8", "--time-limit", "1")
    code, out, err = run_cli(capsys, *args, "--json")
    assert code == 0, err
    full = json.loads(out)["ours"]
    assert full["stopped_by"] == "convergence" and full["gap"] <= 1e-11
    code, out, err = run_cli(capsys, *args, "--our-time-limit", "1e-6", "--json")
    assert code == 0, err
    limited = json.loads(out)["ours"]
    assert limited["stopped_by"] == "time limit"
    assert limited["lower"] <= full["lower"] and limited["upper"] >= full["upper"]
    assert limited["gap"] > full["gap"] and limited["cut_nodes"] > 0 and limited["nodes"] < full["nodes"]
    code, out, _ = run_cli(capsys, *args, "--our-time-limit", "1e-6")
    ours = next(line for line in out.splitlines() if line.startswith("  ours "))
    assert code == 0 and ours.endswith(", stopped by its time limit"), out


@pytest.mark.parametrize("value", ["0", "-1", "nan", "604801", "soon"])
def test_a_bad_our_time_limit_is_one_line_and_exit_2(capsys, value):
    """--our-time-limit takes what synth's --time-limit takes, refused in the one wording."""
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--our-time-limit", value)
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("error: --our-time-limit: ") and "or omit --our-time-limit (no limit)" in err


@pytest.mark.parametrize(("command", "horizon"), [("storm", "0"), ("paynt", "0"), ("storm", "5000"),
                                                  ("paynt", "1001")])
def test_the_peers_take_synths_horizons(capsys, command, horizon):
    """--horizon means the same step bound to the peers as to synth: one range, one refusal."""
    code, out, err = run_cli(capsys, "peer", command, "specs/phi1_trust.toml", "--horizon", horizon)
    _, _, synth_err = run_cli(capsys, "synth", "specs/phi1_trust.toml", "--horizon", horizon)
    assert code == 2 and out == "" and err == synth_err
    assert f"expected an integer from 1 to 1000, got {horizon}" in err


@pytest.mark.parametrize("command", ["storm", "paynt"])
def test_a_product_past_the_limit_is_refused_before_it_is_built(capsys, command):
    """At --horizon 1000 the paper's town's product would hold about 2 million grid states (some
    5 GB while built): refused at once, naming the largest horizon that fits."""
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    started = time.perf_counter()
    code, out, err = run_cli(capsys, "peer", command, "specs/phi1_trust.toml", "--horizon", "1000")
    assert time.perf_counter() - started < 30
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err
    # the grid a step: roads x trust levels x DFA states x last (h, e), as the loaded problem has them
    from trustroute.app.peers import ComparedProblem, loaded_problem
    from trustroute.core import defaults
    from trustroute.policies.logic.dfa import build_dfa

    spec, pomdp = loaded_problem(ComparedProblem("specs/phi1_trust.toml"))
    outcomes = 4 if pomdp.driver.depends_on_performance else 2
    step = pomdp.n_states * pomdp.n_trust * build_dfa(spec).n_states * outcomes
    assert f"--horizon: the product POMDP handed to the peer would have {step * 1001:,} grid states" in err
    largest = defaults.MAX_PEER_PRODUCT // step - 1   # steps 0..H
    assert f"(fix: pass --horizon {largest} or less, or use a smaller town)" in err


def test_a_long_comparison_names_its_step_on_stderr_and_json_silences_it(capsys, monkeypatch):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    from trustroute.policies import resolve

    monkeypatch.setattr(resolve, "PROGRESS_AFTER", 0.0)
    monkeypatch.setattr(resolve, "PROGRESS_EVERY", 0.01)
    args = ("peer", "storm", "specs/phi1_trust.toml", "--horizon", "6", "--time-limit", "1")
    code, out, err = run_cli(capsys, *args, "--json")
    assert code == 0 and err == ""
    states = json.loads(out)["product_states"]
    code, _, err = run_cli(capsys, *args)
    steps = {line.rsplit(" (", 1)[0] for line in err.splitlines()}
    assert code == 0 and steps <= {"peer storm: exporting the product POMDP", "peer storm: our search",
                                   f"peer storm: Storm on {states:,} product states"}
    assert "peer storm: our search" in steps, err


def test_the_text_rounds_paynts_lower_bound_down_as_ours():
    """PAYNT's value is a lower bound of Pr_max, set beside our L: a value a hair below 1 reads
    0.999999, as our L would, never 1.000000."""
    from trustroute.harness.commands.peer import paynt_lines

    value = 1.0 - 4e-8
    result = {"spec": "phi1_trust", "file": "specs/phi1_trust.toml", "horizon": 6, "product_states": 10,
              "paynt": {"value": value, "found": True, "seconds": 1.0, "memory_nodes": 1, "note": ""},
              "ours": {"lower": value, "upper": 1.0, "gap": 4e-8, "seconds": 1.0}, "within_ours": True}
    lines = paynt_lines(result)
    assert "  paynt  0.999999  " in lines[1], lines
    assert "  ours   [0.999999, 1.000000]" in lines[2], lines


@pytest.mark.parametrize("extra", [0, 2])
def test_storm_exact_of_the_baseline_route_equals_our_exact_value_as_a_fraction(capsys, tmp_path, town,
                                                                               driver, extra):
    """`peer storm --exact` end to end: with the packaged model to 3 decimals given as --driver
    (its rows sum to 1 as printed, so the exact process is the route's chain), the rational the
    command prints is our exact value of the baseline route (tests/policies/synthesis/exact_joint.py,
    in integers) as a Fraction, inside our certified [L, U]; a longer --horizon does not move it."""
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    from fractions import Fraction

    from tests.policies.peer.decimal_model import RoutePolicy, decimal_model
    from tests.policies.synthesis.exact_joint import exact_joint_value
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.routing.free import baseline_route

    model_path = tmp_path / "driver_to_3_decimals.json"
    model_path.write_text(json.dumps(decimal_model(driver).to_dict()))
    spec = load_spec("specs/phi1_trust.toml", town)
    route = baseline_route(town, spec)
    horizon = len(route) - 1 + extra
    args = ["peer", "storm", "specs/phi1_trust.toml", "--driver", str(model_path), "--exact",
            *(["--horizon", str(horizon)] if extra else [])]
    code, out, err = run_cli(capsys, *args, "--json")
    assert code == 0, err
    result = json.loads(out)
    storm = Fraction(result["storm_exact"]["value"])
    ours = exact_joint_value(build_pomdp(town, load_driver_model(model_path)), spec, horizon,
                             policy=RoutePolicy(town, route))
    assert isinstance(ours, Fraction) and storm == ours, (float(storm), float(ours))
    assert 0 < storm < 1 and result["route"] == route and result["horizon"] == horizon
    assert Fraction(result["ours"]["lower"]) <= storm <= Fraction(result["ours"]["upper"])
    assert result["within_ours"]
    code, out, _ = run_cli(capsys, *args)
    assert code == 0 and f"= {storm.numerator}/{storm.denominator}" in out and "within ours: yes" in out


def test_storm_exact_with_a_horizon_that_cuts_the_route_is_one_line_and_exit_2(capsys):
    pytest.importorskip("stormpy", reason="needs the optional extra: pip install -e '.[peer]'")
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--exact", "--horizon", "5")
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "--horizon: the baseline route drives 6 junctions" in err and "pass --horizon 6 or more" in err


@pytest.mark.parametrize("given", [["--time-limit", "5"], ["--depth", "4", "--max-nodes", "100"],
                                   ["--resolution", "2"], ["--our-time-limit", "5"]])
def test_storm_exact_refuses_the_options_of_the_bounds_it_would_not_use(capsys, given):
    """An option of the bounds given with --exact (its default too, written out) is one line and
    exit 2 naming it, before any model is built."""
    code, out, err = run_cli(capsys, "peer", "storm", "specs/phi1_trust.toml", "--exact", *given)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert all(flag in err for flag in given if flag.startswith("--")) and "drop --exact" in err
