"""A large model-engine study end to end: `trustroute study` of 4,000 participants x 4 episodes
(phi1, phi2 x aware, free), run, consolidated, analysed and reported (target <= 60 s), against the
bare vectorised simulation of the same 16,000 episodes (simulate_batch, one call per cell) measured
in the same run as the baseline. In-process (--workers 1), so the ratio does not depend on how many
cores the machine lends; synthesized policies come from the usual policy cache (built before
timing).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PARTICIPANTS = 4000
TARGET_SECONDS = 60.0
CONFIG = """[study]
participants = {participants}
seed = 5
engine = "model"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
"""


def _bare_batch(config_path: Path) -> float:
    """Seconds to simulate every episode of the study with simulate_batch (no logs, no files)."""
    from trustroute.harness.simulation.model_engine import simulate_batch
    from trustroute.harness.study.config import load_study_config
    from trustroute.harness.study.context import study_context

    config = load_study_config(config_path)
    context = study_context(config)
    started = time.perf_counter()
    for spec in config.spec_names:
        for condition in config.condition_names:
            simulate_batch(context.setup(spec, condition), context.policies[(spec, condition)],
                           config.participants, np.random.default_rng(1))
    return time.perf_counter() - started


def run() -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="trustroute-bench-") as folder:
        config = Path(folder) / "large.toml"
        config.write_text(CONFIG.format(participants=PARTICIPANTS))
        baseline = _bare_batch(config)  # also fills the policy cache
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "trustroute", "study", str(config), "--out",
                        str(Path(folder) / "study"), "--workers", "1", "--quiet"], check=True,
                       stdout=subprocess.DEVNULL)
        seconds = time.perf_counter() - started
    return [{
        "name": "study.model_engine.4000_participants.seconds",
        "value": seconds, "unit": "s", "target": TARGET_SECONDS, "episodes": PARTICIPANTS * 4,
        "baseline": baseline, "ratio": seconds / baseline,
        "baseline_what": "simulate_batch of the same 16,000 episodes (no logs, no files, no analysis)",
        "what": "trustroute study --workers 1: run, batch parts, consolidation, analysis, report",
    }]
