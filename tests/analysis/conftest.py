"""A small finished model-engine study (aware vs free on φ1 and φ2), shared by the analysis tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def model_study(tmp_path_factory) -> Path:
    from trustroute.harness.study.config import load_study_config
    from trustroute.harness.study.runner import run_and_consolidate

    root = tmp_path_factory.mktemp("study")
    cache = tmp_path_factory.mktemp("policies")
    config_path = root / "study.toml"
    config_path.write_text(f"""[study]
name = "analysis-fixture"
participants = 12
seed = 3
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
policy_cache = "{cache}"
""")
    config = load_study_config(config_path)
    run_and_consolidate(config, root / "out", 1, None, progress=False, echo=lambda *_: None)
    return root / "out"
