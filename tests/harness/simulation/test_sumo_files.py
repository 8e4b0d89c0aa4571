"""`trustroute run --sumo-files DIR`: files that plain SUMO opens, and SUMO's own FCD of the episode."""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from tests.cli import run_cli
from tests.harness.helpers import SPECS
from trustroute.networks.sumo_net import find_binary


@pytest.mark.slow
def test_sumo_files_open_in_plain_sumo(tmp_path, capsys):
    files, logs = tmp_path / "sumo", tmp_path / "logs"
    code, out, err = run_cli(capsys, "run", "--spec", str(SPECS / "phi1.toml"), "--seed", "3",
                             "--sumo-files", str(files), "--out", str(logs))
    assert code == 0, err
    for name in ("episode.sumocfg", "net.net.xml", "routes.rou.xml", "fcd.xml"):
        assert (files / name).stat().st_size > 0, name
    # SUMO's FCD is the episode: the ego's positions are those of the kinematics log.
    kinematics = pd.read_parquet(logs / "kinematics.parquet")
    ego = [(float(v.get("x")), float(v.get("y"))) for step in ET.parse(files / "fcd.xml").getroot()
           for v in step if v.get("id") == "ego"]
    np.testing.assert_allclose(np.array(ego), kinematics[["x", "y"]].to_numpy(), atol=0.01)
    # The config loads in the stock sumo binary (no trustroute) and drives the ego's route.
    result = subprocess.run([find_binary("sumo"), "-c", "episode.sumocfg", "--no-step-log", "true"],
                            cwd=files, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "Error" not in result.stderr and "ignoring" not in result.stderr, result.stderr
    replayed = {v.get("id") for step in ET.parse(files / "fcd.replay.xml").getroot() for v in step}
    assert "ego" in replayed
    routes = ET.parse(files / "routes.rou.xml").getroot()
    ego_route = routes.find("vehicle[@id='ego']/route").get("edges").split()
    roads = pd.read_parquet(logs / "roads.parquet")
    assert ego_route == roads["directed_road"].tolist()
