"""`make test`'s two lanes (tests/suite.py): the wall-clock lane's files and the ledger that makes
sure every test runs in exactly one lane."""

from __future__ import annotations

import gc
import threading
import time
from pathlib import Path

from tests.conftest import GC_THRESHOLD
from tests.suite import REPO, applies, await_collection, lanes_disagree, marked_files


def test_marked_files_are_the_files_that_apply_the_waiting_marks():
    files = marked_files()
    assert "tests/harness/live/test_browser_wheel.py" in files
    assert "tests/policies/peer/test_paynt.py" in files          # two tests of its many
    assert "tests/harness/live/test_live_security.py" not in files   # a live test that does not wait
    assert marked_files(("serial",)) == ["tests/harness/live/test_browser.py"]
    assert all(applies((REPO / name).read_text()) for name in files)
    mark = "pytest.mark"
    assert applies(f"pytestmark = [{mark}.slow, {mark}.wallclock]")
    assert applies(f"@{mark}.serial\ndef test_x(): ...", ("serial",))
    assert not applies(f"@{mark}.wallclocked")
    assert not applies(f"@{mark}.slow")


def _write(folder: Path, lane: str, kind: str, ids: list[str]) -> None:
    path = folder / lane / "ledger" / "run0" / f"gw0.{kind}"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(f"{node}\n" for node in ids))


def test_the_ledger_agrees_only_when_the_wall_clock_lane_ran_what_the_other_left_out(tmp_path):
    _write(tmp_path, "computing", "kept", ["a.py::fast"])
    _write(tmp_path, "computing", "left-out", ["b.py::paced", "c.py::browser"])
    _write(tmp_path, "wallclock", "kept", ["b.py::paced", "c.py::browser"])
    assert lanes_disagree(tmp_path) == ""

    _write(tmp_path, "wallclock", "kept", ["b.py::paced"])
    message = lanes_disagree(tmp_path)
    assert "1 test(s) left out by the CPU-bound lane did not run" in message
    assert "c.py::browser" in message

    _write(tmp_path, "wallclock", "kept", ["b.py::paced", "c.py::browser", "a.py::fast"])
    assert "1 ran in both ['a.py::fast']" in lanes_disagree(tmp_path)


def test_the_wall_clock_lane_waits_for_every_worker_s_collection_or_its_timeout(tmp_path):
    """await_collection returns once as many `kept` ledgers as workers exist, not at the first
    one, and after its timeout when a worker never writes one."""
    ledger = tmp_path / "computing" / "ledger" / "run0"
    ledger.mkdir(parents=True)
    (ledger / "gw0.kept").write_text("")
    (ledger / "gw0.left-out").write_text("")
    timer = threading.Timer(0.6, lambda: (ledger / "gw1.kept").write_text(""))
    started = time.monotonic()
    timer.start()
    await_collection(ledger, 2, timeout=30)
    assert 0.6 <= time.monotonic() - started < 10
    started = time.monotonic()
    await_collection(ledger, 3, timeout=0.5)
    assert time.monotonic() - started >= 0.5


def test_a_test_runs_with_the_collected_objects_frozen_out_of_the_collector():
    assert gc.get_threshold() == GC_THRESHOLD and gc.get_freeze_count() > 0
