"""benchmarks/bench_peers.py: every side of a row carries the load average at its start beside its
wall time (the machine is shared), in the JSON row and in the table on stderr."""

from __future__ import annotations

import pytest

from benchmarks import bench_peers

pytest.importorskip("stormpy", reason="the peer table needs the optional extra: pip install -e '.[peer]'")
pytest.importorskip("paynt", reason="the peer table needs the optional extra: pip install -e '.[peer]'")


def test_every_side_of_a_row_carries_the_load_average_at_its_start(capsys):
    [row] = bench_peers.run(problems=(("paper_phi1_h20", "paper", "phi1", 20),))
    assert 0 < row["ours"]["seconds"]
    for side in ("ours", "storm", "paynt"):
        assert isinstance(row[side]["load_average_1min"], float) and row[side]["load_average_1min"] >= 0
    line = capsys.readouterr().err.strip()
    assert line.startswith("paper_phi1_h20") and f"load {row['ours']['load_average_1min']:.1f}" in line
