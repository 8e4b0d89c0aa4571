"""`trustroute.synthesize(..., population=...)`: a driver population's synthesis through the API,
for a spec that tests the hidden trust."""

from __future__ import annotations

import json

import pytest

import trustroute
from trustroute.core.errors import InputError
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH


@pytest.mark.slow
def test_api_synthesizes_a_trust_state_spec_for_a_population(tmp_path):
    out = tmp_path / "policy.json"
    found = trustroute.synthesize("specs/phi1_trust.toml", horizon=10, population=EXAMPLE_POPULATION_PATH,
                                  out=out)
    assert 0 < found.lower <= found.upper
    assert [v.name for v in found.type_values] == ["builder", "flat", "wary"]
    document = json.loads(out.read_text())
    assert document["kind"] == "joint-belief" and document["objective"] == "bayes"
    assert document["lower"] == found.result.lower
    with pytest.raises(InputError, match="population: a driver model and a driver population were both"):
        trustroute.synthesize("phi1", driver=trustroute.load_driver_model(),
                              population=EXAMPLE_POPULATION_PATH)


def test_a_converged_bayes_population_synthesis_says_so_at_a_tau_below_the_rounding_margin():
    """The search closes its gap on the values it computes; the reported L and U are rounded
    outward (a few 1e-13 apart), which is no reason to call it stopped by its time limit."""
    found = trustroute.synthesize("phi1", horizon=6, population=EXAMPLE_POPULATION_PATH, tau=1e-15)
    assert found.result.stats.converged
    assert 0 < found.upper - found.lower < 1e-11
    assert found.result.stopped_by == "convergence"
