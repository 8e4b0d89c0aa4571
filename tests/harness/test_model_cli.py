"""`trustroute model`: the summary of the default town and driver model, and its error path."""

from __future__ import annotations

import json

import numpy as np

from tests.cli import run_cli
from trustroute.participants.driver_model import DEFAULT_DRIVER_MODEL_PATH


def test_summary_text(capsys):
    code, out, err = run_cli(capsys, "model")
    assert code == 0 and err == ""
    assert "12 junctions, 18 two-way roads, 36 states" in out
    assert "trust levels 1..7" in out
    assert "performance-dependent dynamics: False" in out


def test_summary_json_matches_the_files(capsys, town, driver):
    code, out, _ = run_cli(capsys, "model", "--json")
    assert code == 0
    summary = json.loads(out)
    assert summary["states"] == len(town.states) == 36
    assert sum(summary["incidents_per_type"].values()) == 36
    for kind, count in summary["incidents_per_type"].items():
        assert count == sum(1 for v in town.incidents.values() if v == kind)
    assert summary["town_hash"] == town.content_hash[:12]
    assert summary["driver_hash"] == driver.content_hash[:12]
    for i, kind in enumerate(driver.incident_types):
        assert np.allclose(summary["takeover_probability"][kind], driver.takeover_probability[i],
                           atol=5e-4)


def test_model_not_covering_the_town_exits_2(tmp_path, capsys):
    data = json.loads(DEFAULT_DRIVER_MODEL_PATH.read_text())
    data["incident_types"].remove("pedestrian")
    for key in ("takeover_probability", "trust_transition", "trust_free_takeover_probability"):
        del data[key]["pedestrian"]
    path = tmp_path / "driver.json"
    path.write_text(json.dumps(data))
    code, out, err = run_cli(capsys, "model", "--driver", str(path))
    assert code == 2 and out == ""
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert "uses incident 'pedestrian' which the model does not cover" in err
    assert "(fix: add 'pedestrian'" in err


def test_unknown_option_is_a_usage_error(capsys):
    code, _, err = run_cli(capsys, "model", "--no-such-option")
    assert code == 2
    assert "Traceback" not in err


def test_one_way_roads_are_counted_apart_from_two_way_ones(tmp_path, capsys):
    """A square with one one-way road: 3 two-way and 1 one-way road, 7 directed roads (states)."""
    from tests.networks.test_road_geometry import square

    data = square(one_way=[["A", "B"]])
    del data["incidents"]["B-A"]
    path = tmp_path / "square.json"
    path.write_text(json.dumps(data))
    code, out, err = run_cli(capsys, "model", "--town", str(path))
    assert code == 0, err
    assert "4 junctions, 3 two-way and 1 one-way roads, 7 states" in out
    code, out, _ = run_cli(capsys, "model", "--town", str(path), "--json")
    summary = json.loads(out)
    two_way = summary["roads"] - summary["one_way_roads"]
    assert summary["states"] == 2 * two_way + summary["one_way_roads"] == 7
