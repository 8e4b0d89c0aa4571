"""The independent peers beside ours on one problem (docs/peers.md): the problem loaded as every
command loads it, exported as the explicit product a peer is given, and both sides' bounds;
`trustroute peer storm` and `trustroute peer paynt` print them. The peers themselves are the
optional `[peer]` extra, imported only when a comparison runs."""

from __future__ import annotations

from trustroute.app.inputs import load_inputs
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.peer.product_pomdp import check_exportable, explicit_product
from trustroute.policies.trust_state_synthesis.search import joint_bounds


def exported_problem(spec_path: str, town_path: str | None, driver_path: str | None,
                     horizon: int | None) -> tuple:
    """(spec, our POMDP, the explicit product a peer is given) for one comparison."""
    inputs = load_inputs(spec_path, town_path, driver_path)
    spec = inputs.spec
    check_exportable(spec)
    pomdp = build_pomdp(inputs.town, inputs.model)
    return spec, pomdp, explicit_product(pomdp, spec, horizon)


def our_bounds(pomdp, spec, horizon: int | None, depth: int, max_nodes: int):
    """Our side of a comparison: the trust-state search's bounds on the same problem."""
    return joint_bounds(pomdp, spec, depth=depth, horizon=horizon, max_nodes=max_nodes)


def storm_comparison(spec_path: str, town_path: str | None, driver_path: str | None,
                     horizon: int | None, time_limit: float, resolution: int, depth: int,
                     max_nodes: int) -> dict:
    """Both sides' bounds and seconds, JSON-ready."""
    from trustroute.policies.peer.storm import require_storm, run_storm

    require_storm("trustroute peer storm")
    spec, pomdp, product = exported_problem(spec_path, town_path, driver_path, horizon)
    storm = run_storm(product, time_limit=time_limit, resolution=resolution)
    ours = our_bounds(pomdp, spec, horizon, depth, max_nodes)
    return {"spec": spec.name, "file": spec.source_path, "horizon": horizon,
            "product_states": product.n_states, "storm": storm.to_dict(), "ours": ours.to_dict(),
            "overlap": bool(max(storm.lower, ours.lower) <= min(storm.upper, ours.upper) + 1e-9)}


def paynt_comparison(spec_path: str, town_path: str | None, driver_path: str | None,
                     horizon: int | None, time_limit: float, max_states: int, depth: int,
                     max_nodes: int) -> dict:
    """PAYNT's controller value beside our bounds, JSON-ready."""
    from trustroute.policies.peer.paynt import require_paynt, run_paynt

    require_paynt("trustroute peer paynt")
    spec, pomdp, product = exported_problem(spec_path, town_path, driver_path, horizon)
    paynt = run_paynt(product, time_limit=time_limit, max_states=max_states)
    ours = our_bounds(pomdp, spec, horizon, depth, max_nodes)
    return {"spec": spec.name, "file": spec.source_path, "horizon": horizon,
            "product_states": product.n_states, "paynt": paynt.to_dict(), "ours": ours.to_dict(),
            "within_ours": bool(paynt.lower <= ours.upper + paynt.precision)}
