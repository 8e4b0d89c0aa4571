"""The API's errors name its keyword arguments, never the CLI's flags, and its seeds and names
follow the CLI's rules."""

from __future__ import annotations

import pytest

import trustroute
from trustroute.app.runs import EpisodeSettings
from trustroute.core.errors import InputError


@pytest.mark.parametrize(("call", "named"), [
    (lambda: trustroute.load_town("nope"), "as town or a packaged town name"),
    (lambda: trustroute.synthesize("phi1", horizon=-1), "horizon: horizon must be at least 1"),
    (lambda: trustroute.run_episode("phi1", settings=EpisodeSettings(engine="model", initial_trust=0)),
     "initial_trust: 0 is not a trust level"),
    (lambda: trustroute.run_episode("phi1", engine="model", initial_trust=0),
     "initial_trust: 0 is not a trust level"),
])
def test_api_errors_name_keyword_arguments(call, named):
    with pytest.raises(InputError, match=named) as caught:
        call()
    assert "--" not in str(caught.value)


def test_analyze_names_its_belief_source_argument(tmp_path):
    with pytest.raises(InputError) as caught:
        trustroute.analyze(tmp_path, belief_source="bogus")
    assert "--" not in str(caught.value)


@pytest.mark.parametrize("seed", [-1, 2**31, 1.5, "3"])
def test_an_episode_seed_follows_the_cli_rule(seed):
    with pytest.raises(InputError, match=rf"seed: expected an integer from 0 to 2147483647, got {seed!r}"):
        trustroute.run_episode("phi1", engine="model", seed=seed)


def test_the_largest_seed_and_a_numpy_seed_run():
    import numpy as np

    assert trustroute.run_episode("phi1", engine="model", seed=2**31 - 1).summary["junctions"] > 0
    assert trustroute.run_episode("phi1", engine="model", seed=np.int64(3)).summary["junctions"] > 0


@pytest.mark.parametrize(("call", "what"), [(lambda: trustroute.load_town(""), "town"),
                                            (lambda: trustroute.load_spec(""), "spec"),
                                            (lambda: trustroute.load_driver_model(""), "driver model")])
def test_an_empty_name_is_said_to_be_empty(call, what):
    with pytest.raises(InputError, match=f"the {what} name is empty"):
        call()
