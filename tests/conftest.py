"""Shared fixtures: a temporary cache root, the packaged default town, driver model and trust POMDP."""

from __future__ import annotations

import pytest

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
