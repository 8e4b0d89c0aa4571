"""The one marker of the tests that need the optional `cities` extra (sumo-rl's RESCO scenarios,
located without importing sumo_rl). `make test` installs the extra, so there they always run."""

from __future__ import annotations

import importlib.util

import pytest

needs_cities_extra = pytest.mark.skipif(importlib.util.find_spec("sumo_rl") is None,
                                        reason="needs the optional extra: pip install -e '.[cities]'")
