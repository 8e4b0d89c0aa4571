"""Shared fixtures: a temporary cache root, the packaged default town, driver model and trust POMDP."""

from __future__ import annotations

import gc
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import settings

from tests.harness.helpers import run_study
from tests.suite import CACHE_ENV, LEDGER_ENV
from trustroute.core.output_files import file_lock
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.model.trust_pomdp import build_pomdp

# The property tests draw the same examples on every run (`derandomize`: a seed derived from each
# test), as every other draw of the suite comes from a fixed seed: a run's outcome and its time do
# not depend on chance. Random draws would vary the suite by minutes: about one random town in six
# of the unbounded synthesis' property test needs its whole work limit (90 s on an idle core).
# `pytest --hypothesis-profile=explore` draws new examples each run, to look for failures beyond the
# fixed ones; no example database is written either way.
settings.register_profile("suite", derandomize=True, database=None)
settings.register_profile("explore", database=None)
settings.load_profile("suite")

# The garbage collector of a pytest process: a worker holds a million objects by the end of its
# share (the modules, the collected tests, the session fixtures), and each full collection scans
# them all. What exists once collection is done lives to the end, so it is frozen out of the
# scans; young collections run every GC_THRESHOLD allocations instead of 700.
GC_THRESHOLD = (10_000, 10, 10)


def _freeze_collected() -> None:
    gc.collect()
    gc.freeze()
    gc.set_threshold(*GC_THRESHOLD)


@pytest.fixture(scope="session", autouse=True)
def temporary_cache(tmp_path_factory):
    """Every test caches nets and policies in one temporary root (XDG_CACHE_HOME), never in the
    real ~/.cache; one per run, shared by the run's pytest-xdist workers (the base temp folder
    they share, or the root tests/suite.py gives all its runs), so a policy or net built by one
    test is reused by the next on any worker. The cache's entries are filled under locks and
    renamed into place (core/output_files.py), which this sharing exercises."""
    if os.environ.get(CACHE_ENV):
        root = Path(os.environ[CACHE_ENV])   # tests/suite.py: one root for its lanes
    else:
        base = tmp_path_factory.getbasetemp()
        if os.environ.get("PYTEST_XDIST_WORKER"):
            base = base.parent   # <run>/popen-gwN: the run's own folder is the workers' common one
        root = base / "xdg-cache"
    root.mkdir(exist_ok=True)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("XDG_CACHE_HOME", str(root))
        yield root


def shared_fixture(cache: Path, name: str, build: Callable[[Path], None]) -> Path:
    """The folder `name` in the run's cache root (`temporary_cache`), filled by `build(folder)` once
    per run by whichever pytest-xdist worker asks first: a module's tests may be shared out to both
    workers, and a fixture that runs a whole study would run it on each. The others wait on the
    folder's lock, then read what it built; a build cut short (no `.built` mark) is built again."""
    folder = cache / "test-fixtures" / name
    with file_lock(folder.with_name(f"{name}.lock"), f"test fixture {name}", wait=True):
        if not (folder / ".built").exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir(parents=True)
            build(folder)
            (folder / ".built").touch()
    return folder


@pytest.fixture(scope="session")
def town():
    return load_town()


@pytest.fixture(scope="session")
def driver():
    return load_driver_model()


@pytest.fixture(scope="session")
def pomdp(town, driver):
    return build_pomdp(town, driver)


@pytest.fixture(scope="session")
def net_path(town, temporary_cache) -> Path:
    """The packaged town's SUMO net, built once into the run's cache root: every module that drives
    SUMO on the packaged town reads this one entry, on any worker and in either lane."""
    return build_net(town).path


MODEL_STUDY = """[study]
name = "analysis-fixture"
participants = 12
seed = 3
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
policy_cache = "{cache}"
"""


def _build_model_study(folder: Path) -> None:
    """The model study in `folder/out` (its config `folder/study.toml`, its policies
    `folder/policies`) and its report, whose `analyze --json --report` is kept in
    `folder/report.json`: written in the build, so no worker writes into the study while another
    reads it."""
    import json

    from click.testing import CliRunner

    from trustroute.harness.cli import cli

    run_study(folder / "study.toml", MODEL_STUDY.format(cache=folder / "policies"), folder / "out")
    result = CliRunner().invoke(cli, ["analyze", str(folder / "out"), "--json", "--report"])
    assert result.exit_code == 0, (result.stderr, result.exception)
    (folder / "report.json").write_text(json.dumps(json.loads(result.stdout)))


@pytest.fixture(scope="session")
def model_study(temporary_cache) -> Path:
    """A small finished model-engine study (aware vs free on φ1 and φ2), shared by the analysis and
    dataset tests: built once per run (`shared_fixture`), its report (report.md, report.html,
    plots/) already written. No test writes into it: a test that changes a study (an export writes
    its key into it) works on a copy."""
    return shared_fixture(temporary_cache, "model-study", _build_model_study) / "out"


@pytest.fixture(scope="session")
def model_report(model_study) -> dict:
    """The JSON of `trustroute analyze MODEL_STUDY --json --report`, run once per run with the
    model study (it must succeed). The report, paired-table and plot tests read its report in the
    model study: each of them would otherwise write the same report again, its plots most of an
    analysis' time."""
    import json

    return json.loads((model_study.parent / "report.json").read_text())


PILOT_STUDY = """[study]
name = "pilot-{seed}"
participants = {participants}
seed = {seed}
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
policy_cache = "{cache}"
{extra}
[population]
report_accuracy = 1.0
"""


@pytest.fixture(scope="session")
def pilot_study(model_study, temporary_cache):
    """make(seed, participants=8, extra=""): a finished model-engine pilot study (aware vs free on
    φ1 and φ2, the model study's policy cache) whose drivers report their exact trust on every road
    (so `fit` counts: a refit takes hundredths of a second), `extra` appended to its config; each
    made once per run (`shared_fixture`, named by its config). No test writes into one."""
    import hashlib

    from trustroute.harness.study.config import load_study_config

    cache = load_study_config(model_study.parent / "study.toml").policy_cache

    def make(seed: int, participants: int = 8, extra: str = "") -> Path:
        text = PILOT_STUDY.format(seed=seed, participants=participants, cache=cache, extra=extra)
        name = f"pilot-{seed}-{hashlib.sha256(text.encode()).hexdigest()[:12]}"
        return shared_fixture(temporary_cache, name,
                              lambda folder: run_study(folder / "pilot.toml", text, folder / "out")) / "out"

    return make


def pytest_collection_modifyitems(config, items):
    """The tests marked `slow` (seconds to minutes each, many of them waiting on the wall clock of a
    live study) first, the rest in their order after them: pytest-xdist hands the items out in this
    order, so the long ones start at once and the short ones fill the workers around them instead
    of a long test starting last and running alone."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def _write_ledger(kind: str, items) -> None:
    """tests/suite.py's ledger: the node ids this process kept (`kept`) or its `-m` left out
    (`left-out`), one file per process and kind."""
    if not (folder := os.environ.get(LEDGER_ENV)):
        return
    path = Path(folder) / f"{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.{kind}"
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as ledger:
        ledger.writelines(f"{item.nodeid}\n" for item in items)


def pytest_deselected(items):
    _write_ledger("left-out", items)


def pytest_collection_finish(session):
    _write_ledger("kept", session.items)
    _freeze_collected()
