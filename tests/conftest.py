"""Shared fixtures: a temporary cache root, the packaged default town, driver model and trust POMDP."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.harness.helpers import run_study
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.model.trust_pomdp import build_pomdp


@pytest.fixture(scope="session", autouse=True)
def temporary_cache(tmp_path_factory):
    """Every test caches nets and policies in one temporary root (XDG_CACHE_HOME), never in the
    real ~/.cache; one per session, so a policy synthesized by one test is reused by the next."""
    with pytest.MonkeyPatch.context() as patch:
        root = tmp_path_factory.mktemp("xdg-cache")
        patch.setenv("XDG_CACHE_HOME", str(root))
        yield root


@pytest.fixture(scope="session")
def town():
    return load_town()


@pytest.fixture(scope="session")
def driver():
    return load_driver_model()


@pytest.fixture(scope="session")
def pomdp(town, driver):
    return build_pomdp(town, driver)


@pytest.fixture(scope="session")
def model_study(tmp_path_factory) -> Path:
    """A small finished model-engine study (aware vs free on φ1 and φ2), shared by the analysis and
    dataset tests."""
    root = tmp_path_factory.mktemp("study")
    cache = tmp_path_factory.mktemp("policies")
    run_study(root / "study.toml", f"""[study]
name = "analysis-fixture"
participants = 12
seed = 3
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
policy_cache = "{cache}"
""", root / "out")
    return root / "out"
