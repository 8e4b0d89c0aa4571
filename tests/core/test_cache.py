"""One cache root for nets and policies, honouring XDG_CACHE_HOME; the policy key carries the
synthesis code's version."""

from __future__ import annotations

from pathlib import Path

from trustroute.core import cache
from trustroute.networks.sumo_net import net_path
from trustroute.policies import resolve
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.synthesis import version


def test_the_suite_runs_on_a_temporary_cache(temporary_cache):
    assert cache.cache_root() == temporary_cache / "trustroute"
    assert Path.home() / ".cache" not in cache.cache_root().parents


def test_xdg_cache_home_moves_every_cache(monkeypatch, tmp_path, town, driver):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    spec = load_spec("specs/phi1.toml", town)
    assert cache.cache_root() == tmp_path / "trustroute"
    assert net_path(town).parent == tmp_path / "trustroute" / cache.NETS
    policies = resolve.aware_cache_path(town, driver, spec, None).parent
    assert policies == tmp_path / "trustroute" / cache.POLICIES


def test_without_xdg_cache_home_the_root_is_under_home(monkeypatch, tmp_path):
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    assert cache.cache_root() == tmp_path / ".cache" / "trustroute"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/dir")  # ignored, as the XDG specification says
    assert cache.cache_root() == tmp_path / ".cache" / "trustroute"


def test_policy_key_changes_with_the_synthesis_version(monkeypatch, town, driver):
    spec = load_spec("specs/phi1.toml", town)
    before = resolve.aware_cache_path(town, driver, spec, None)
    assert before == resolve.aware_cache_path(town, driver, spec, None)
    monkeypatch.setattr(resolve, "SYNTHESIS_VERSION", version.SYNTHESIS_VERSION + "-next")
    after = resolve.aware_cache_path(town, driver, spec, None)
    assert after != before and after.parent == before.parent


def test_the_joint_synthesis_version_keys_the_policies_of_trust_state_specs_only(monkeypatch, town,
                                                                                 driver):
    joint = load_spec("specs/phi1_trust.toml", town)
    plain = load_spec("specs/phi1.toml", town)
    before = [resolve.aware_cache_path(town, driver, spec, None) for spec in (joint, plain)]
    monkeypatch.setattr(resolve, "JOINT_SYNTHESIS_VERSION", version.JOINT_SYNTHESIS_VERSION + "-next")
    after = [resolve.aware_cache_path(town, driver, spec, None) for spec in (joint, plain)]
    assert after[0] != before[0] and after[1] == before[1]


def test_content_hashes_are_computed_once(town, driver):
    spec = load_spec("specs/phi1.toml", town)
    for thing in (town, driver, spec):
        first = thing.content_hash
        assert "content_hash" in vars(thing)  # stored on the object after the first use
        assert thing.content_hash is first


def test_an_entry_is_locked_beside_it_in_the_cache_and_in_the_cache_for_a_folder_of_the_user(
        monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    own = cache.cache_dir(cache.NETS) / "a.net.xml"
    assert cache.entry_lock_path(own) == own.with_name("a.net.xml.lock")
    users = tmp_path / "nets" / "a.net.xml"
    lock = cache.entry_lock_path(users)
    assert lock.parent == tmp_path / "cache" / "trustroute" / cache.LOCKS
    assert lock.name.endswith("-a.net.xml.lock")
    assert cache.entry_lock_path(tmp_path / "other" / "a.net.xml") != lock   # by the entry's path
    (tmp_path / "marker").write_text("a file, where the cache root's parent would be\n")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "marker"))
    assert cache.entry_lock_path(users) == users.with_name("a.net.xml.lock")   # no cache: beside
