"""Shared fixtures: the packaged default town, driver model and trust POMDP."""

from __future__ import annotations

import pytest

from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.model.trust_pomdp import build_pomdp


@pytest.fixture(scope="session")
def town():
    return load_town()


@pytest.fixture(scope="session")
def driver():
    return load_driver_model()


@pytest.fixture(scope="session")
def pomdp(town, driver):
    return build_pomdp(town, driver)
