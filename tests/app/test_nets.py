"""`net_for`: the net a town drives, built nets verified once per file version."""

from __future__ import annotations

import os
from types import SimpleNamespace

import pytest

from trustroute.app import nets


def test_a_built_town_net_is_verified_once_per_file_version(town, tmp_path, monkeypatch):
    """A built town's net is verified (build_net) the first time in a process and again whenever
    the file changed or is gone, not at every episode."""
    net = tmp_path / "town.net.xml"
    builds = []

    def fake_build(town_):
        builds.append(town_)
        net.write_text("<net/>")
        return SimpleNamespace(path=net)

    monkeypatch.setattr(nets, "built_net_path", lambda town_: net)
    monkeypatch.setattr(nets, "build_net", fake_build)
    monkeypatch.setattr(nets, "_VERIFIED_NETS", set())
    assert nets.net_for(town) == net and len(builds) == 1   # absent: built
    assert nets.net_for(town) == net and len(builds) == 1   # unchanged: no second check
    os.utime(net, ns=(0, net.stat().st_mtime_ns + 10**9))
    assert nets.net_for(town) == net and len(builds) == 2   # replaced: verified again
    net.unlink()
    assert nets.net_for(town) == net and len(builds) == 3   # deleted: rebuilt


@pytest.mark.slow   # the csomor town and net are built from packaged plain XML on first use
def test_an_imported_town_drives_its_own_net_at_every_door(capsys):
    from tests.cli import cli_json
    from trustroute.networks.town import load_town

    town = load_town("csomor")
    driven = nets.net_for(town)
    assert driven == nets.town_net_file(town)
    built = cli_json(capsys, "net", "build", "--town", "csomor")
    assert built["paths"]["net"] == str(driven) and built["edges"] > 1000
