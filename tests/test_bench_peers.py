"""benchmarks/bench_peers.py: every side of a row carries the load average at its start beside its
wall time (the machine is shared), in the JSON row and in the table on stderr."""

from __future__ import annotations

import pytest

from benchmarks import bench_peers


def test_every_side_of_a_row_carries_the_load_average_at_its_start(capsys):
    pytest.importorskip("stormpy", reason="the peer table needs the optional extra: pip install -e '.[peer]'")
    pytest.importorskip("paynt", reason="the peer table needs the optional extra: pip install -e '.[peer]'")
    [row] = bench_peers.run(problems=(("paper_phi1_h20", "paper", "phi1", 20),))
    assert 0 < row["ours"]["seconds"]
    for side in ("ours", "storm", "paynt"):
        assert isinstance(row[side]["load_average_1min"], float) and row[side]["load_average_1min"] >= 0
    line = capsys.readouterr().err.strip()
    assert line.startswith("paper_phi1_h20") and f"load {row['ours']['load_average_1min']:.1f}" in line


def test_the_tables_bounds_are_rounded_outward_as_every_printed_bound():
    """A side's [lower, upper] reads rounded outward at the table's five decimals, PAYNT's value (a
    lower bound) rounded down: a lower bound a hair below 1 never reads 1.00000."""
    hair = 1.0 - 4e-9
    side = {"seconds": 1.0, "peak_rss_mb": 100.0, "load_average_1min": 0.5}
    assert bench_peers._cell({**side, "lower": hair, "upper": 0.5 + 4e-9}).startswith("[0.99999, 0.50001] ")
    assert bench_peers._cell({**side, "value": hair, "memory_nodes": 1}).startswith("0.99999 (lower) ")
