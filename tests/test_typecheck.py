"""The package type-checks clean with mypy (the check `make lint` runs, tests/typecheck.py)."""

from __future__ import annotations

import pytest

from tests.typecheck import run_mypy


@pytest.mark.slow
def test_the_package_type_checks_clean():
    done = run_mypy()
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
