"""PAYNT's finite-state controllers on the same product POMDP: never above our certified U, never
above the exact optimum (needs the optional `[peer]` extra)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.policies.trust_specs import random_problem
from trustroute.harness.cli import main
from trustroute.policies.logic.spec import load_spec, spec_from_text
from trustroute.policies.peer.product_pomdp import explicit_product
from trustroute.policies.synthesis.exact_search import exact_optimum
from trustroute.policies.synthesize_spec import synthesize_spec
from trustroute.policies.trust_state_synthesis.search import joint_bounds

pytest.importorskip("paynt", reason="PAYNT tests need the optional extra: pip install -e '.[peer]'")

from trustroute.policies.peer.paynt import PRECISION, run_paynt  # noqa: E402


def road_spec(pomdp, spec):
    """The random spec's start and road sets with a road-only formula: the brute force applies."""
    a, b = (json.dumps(sorted(spec.state_atoms[name])) for name in ("a", "b"))
    text = (f'name = "roads"\nstart = "{spec.start}"\nformula = "F (a & F b)"\n'
            f"[states]\na = {a}\nb = {b}\n")
    return spec_from_text(text, "<road spec>", pomdp.town)


@pytest.mark.parametrize("seed", [21, 22, 23])
def test_paynt_never_exceeds_the_brute_force_optimum_on_small_towns(driver, seed):
    pomdp, spec = random_problem(np.random.default_rng(seed), driver, "trust")
    spec = road_spec(pomdp, spec)
    horizon = 4
    exact = exact_optimum(pomdp, spec, horizon)
    paynt = run_paynt(explicit_product(pomdp, spec, horizon), time_limit=1)
    assert paynt.found and paynt.bound == "lower"
    assert paynt.value <= exact + PRECISION, (paynt, exact)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12])
def test_paynt_never_exceeds_our_certified_upper_bound_with_trust_atoms(driver, seed):
    pomdp, spec = random_problem(np.random.default_rng(seed), driver, "trust")
    paynt = run_paynt(explicit_product(pomdp, spec, 3), time_limit=1)
    exact = joint_bounds(pomdp, spec, depth=0, horizon=3)      # exact at a horizon: gap ~ 0
    assert exact.gap <= 1e-11 and paynt.lower <= exact.upper + PRECISION, (paynt, exact)
    unbounded = run_paynt(explicit_product(pomdp, spec, None), time_limit=1)
    ours = synthesize_spec(pomdp, spec, tau=1e-3, time_limit=10)
    assert unbounded.lower <= ours.upper + PRECISION, (unbounded, ours)


def test_paynt_on_the_paper_town_stays_below_synth_upper_bound(pomdp):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    paynt = run_paynt(explicit_product(pomdp, spec, 8), time_limit=2)
    ours = synthesize_spec(pomdp, spec, tau=1e-3, time_limit=20, horizon=8)
    assert paynt.found and 0 < paynt.value <= ours.upper + PRECISION, (paynt, ours)


def _main(args: list[str], capsys) -> tuple[int, str]:
    capsys.readouterr()
    with pytest.raises(SystemExit) as exited:
        main(args)
    return exited.value.code, capsys.readouterr().err


def test_inputs_paynt_cannot_take_exit_2_with_one_line(capsys):
    code, err = _main(["peer", "paynt", "specs/phi1.toml", "--horizon", "4", "--time-limit", "1"], capsys)
    assert code == 2 and "belief atoms (hightrust)" in err and len(err.strip().splitlines()) == 1
    code, err = _main(["peer", "paynt", "specs/phi1_trust.toml", "--horizon", "4", "--max-states", "10"],
                      capsys)
    assert code == 2 and "more than PAYNT is run on here (10)" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_cli_reports_the_value_as_a_lower_bound(capsys):
    capsys.readouterr()
    main_args = ["peer", "paynt", "specs/phi1_trust.toml", "--horizon", "6", "--time-limit", "1", "--json"]
    with pytest.raises(SystemExit) as exited:
        main(main_args)
    assert exited.value.code in (0, None)
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["paynt"]["bound"] == "lower" and result["within_ours"]
    assert result["paynt"]["lower"] <= result["ours"]["upper"] + PRECISION
