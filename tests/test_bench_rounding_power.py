"""The rounding-power benchmark counts what the checks see with a margin removed: its row's counts
(all, the suite's share, per file and test), and a run that replaces the outward rounding in a
pytest process of its own and finds the unbounded run whose L comes out above 1."""

from __future__ import annotations

import pytest

from benchmarks import bench_rounding_power

UNBOUNDED = "tests/policies/synthesis/test_rounding.py::test_unbounded_bounds_lie_in_the_unit_interval"


def test_the_row_counts_failures_of_all_checks_of_the_suite_and_per_test():
    slow = {"tests/a.py::test_x[2]": False, "tests/a.py::test_x[10]": True, "tests/a.py::test_x[3]": True,
            "tests/b.py::test_y": False}
    failed = {"tests/a.py::test_x[10]": "AssertionError: (10,)",
              "tests/a.py::test_x[2]": "AssertionError: (2,)"}
    row = bench_rounding_power.summary("v", slow, failed, ["m.f"])
    assert (row["name"], row["value"], row["checks"], row["suite"]) == (
        "rounding_power_v", 2, 4, {"failed": 1, "checks": 2})
    assert row["files"]["tests/a.py"] == {"failed": 2, "checks": 3, "suite": {"failed": 1, "checks": 1}}
    assert row["files"]["tests/b.py"] == {"failed": 0, "checks": 1, "suite": {"failed": 0, "checks": 1}}
    test_x = row["tests"]["tests/a.py::test_x"]
    assert (test_x["failed"], test_x["checks"]) == (2, 3)
    assert list(test_x["failing"]) == ["2", "10"]       # seeds as numbers
    assert row["replaced"] == ["m.f"]


@pytest.mark.slow
def test_without_the_outward_rounding_an_unbounded_lower_bound_lies_above_one():
    checks = [f"{UNBOUNDED}[{seed}]" for seed in (0, 3)]
    row = bench_rounding_power.measure("no_outward_rounding", checks)
    assert (row["value"], row["checks"]) == (1, 2)
    failing = row["tests"][UNBOUNDED]
    assert list(failing["failing"]) == ["3"]
    assert "trustroute.policies.synthesis.rounding.widen" in row["replaced"]
    assert bench_rounding_power.measure("plain_mixture", checks)["value"] == 0
