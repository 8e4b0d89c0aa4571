"""A tiny live study (one participant, one trial of φ1 on the trust-free route) for the live tests."""

from __future__ import annotations

import pytest

from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.config import load_study_config

TINY = """[study]
name = "tiny-live"
participants = {participants}
seed = 1
engine = "live"
specs = {specs}
conditions = ["free"]
"""


def tiny_config(tmp_path, participants: int = 2, specs: tuple[str, ...] = ("phi1",)):
    path = tmp_path / "live.toml"
    path.write_text(TINY.format(participants=participants, specs=list(specs)).replace("'", '"'))
    return load_study_config(path)


@pytest.fixture
def live_study(tmp_path):
    """An open live study at pace 1000 in tmp_path/study (closed after the test)."""
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions(pace=1000.0)).open()
    yield study
    study.close()
