"""benchmarks/bench_joint_time_limit.py: each row carries the load average beside its wall time,
as bench_synthesis_time_limit's rows do (the machine is shared; a ratio to the limit is read
against it)."""

from __future__ import annotations

from benchmarks import bench_joint_time_limit


def test_a_row_carries_the_load_average_beside_its_wall_time():
    [row] = bench_joint_time_limit.run(runs=(("paper", 0.5),))
    assert row["name"] == "joint_time_limit_paper_0.5s"
    assert row["ratio_to_limit"] == row["seconds"] / 0.5
    assert isinstance(row["load_average_1min"], float) and row["load_average_1min"] >= 0
