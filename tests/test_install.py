"""`pip install .` puts only the `trustroute` package and its dist-info at the top of site-packages."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_wheel_has_one_top_level_package(tmp_path):
    # No build isolation: nothing is downloaded; the dev extra pins the setuptools that builds it.
    command = [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "--no-build-isolation",
               "--quiet", "--wheel-dir", str(tmp_path)]
    built = subprocess.run(command, check=True, capture_output=True, text=True)
    # A quiet install: the data folders are declared as package data, so setuptools has nothing to say.
    assert "BuildBackendWarning" not in built.stderr + built.stdout
    (wheel,) = tmp_path.glob("trustroute-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {name.split("/")[0] for name in names}
    assert top == {"trustroute", f"{wheel.name.split('-')[0]}-{wheel.name.split('-')[1]}.dist-info"}
    # The subpackages and their data ship inside the one namespace.
    for path in ("trustroute/harness/simulation/gym_env.py", "trustroute/networks/data/town01_carla.json",
                 "trustroute/networks/data/csomor/csomor.edg.xml.gz",
                 "trustroute/networks/data/csomor/README.md",
                 "trustroute/networks/data/csomor/LICENSE-routerl.txt",
                 "trustroute/participants/data/driver_model.json", "trustroute/core/specs/phi1.toml",
                 "trustroute/harness/live/pages/station.html", "trustroute/harness/live/pages/station.js"):
        assert path in names
