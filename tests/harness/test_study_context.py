"""The study context is built per config: settings that change the drivers change the context."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.context import study_context

STUDY = """[study]
participants = 3
seed = 5
engine = "model"
specs = ["phi1"]
conditions = ["free"]
"""


def _config(tmp_path: Path, name: str, population: str):
    path = tmp_path / name
    path.write_text(STUDY + population)
    return load_study_config(path)


def test_configs_differing_only_in_population_get_their_own_context(tmp_path):
    """An in-process sweep over [population] settings must run each setting's drivers."""
    # The same file name in two folders: the configs differ in [population] and nothing else.
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    narrow = _config(tmp_path / "a", "study.toml", "[population]\nconcentration = 1000.0\n")
    wide = _config(tmp_path / "b", "study.toml", "[population]\nconcentration = 2.0\ntakeover_spread = 1.0\n")
    wide = type(wide)(**{**wide.__dict__, "source_path": narrow.source_path})
    assert narrow.population != wide.population and narrow.content_hash != wide.content_hash
    first, second = study_context(narrow), study_context(wide)
    assert first.config.population == narrow.population
    assert second.config.population == wide.population
    different = [not np.allclose(a.trust_transition, b.trust_transition)
                 for a, b in zip(first.participants, second.participants, strict=True)]
    assert all(different)
    assert narrow != wide and hash(narrow) != hash(wide)


def test_equal_configs_share_one_context(tmp_path):
    a = _config(tmp_path, "study.toml", "[population]\nconcentration = 30.0\n")
    b = _config(tmp_path, "study.toml", "[population]\nconcentration = 30.0\n")
    assert a == b and hash(a) == hash(b)
    assert study_context(a) is study_context(b)


def test_nominal_and_population_configs_do_not_share_a_context(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    nominal = _config(tmp_path / "a", "study.toml", "")
    varied = _config(tmp_path / "b", "study.toml", "[population]\nconcentration = 5.0\n")
    varied = type(varied)(**{**varied.__dict__, "source_path": nominal.source_path})
    assert study_context(nominal).participants is None
    assert study_context(varied).participants is not None


def test_progress_does_not_split_the_cache(tmp_path):
    """validate_study builds the context with its progress flag; workers forked after it and the
    consolidation ask without one and must get that very context (no policy loaded again)."""
    config = _config(tmp_path, "study.toml", "[population]\nconcentration = 40.0\n")
    first = study_context(config, True)
    assert study_context(config) is first
    assert study_context(config, False) is first


def test_a_forked_worker_inherits_the_context(tmp_path):
    import multiprocessing

    from trustroute.harness.study import context as context_module

    config = _config(tmp_path, "study.toml", "[population]\nconcentration = 50.0\n")
    study_context(config, False)
    fork = multiprocessing.get_context("fork")
    with fork.Pool(1) as pool:
        built_in_worker = pool.apply(_builds_in_worker, (config,))
    assert built_in_worker is False
    assert config in context_module._CONTEXTS


def _builds_in_worker(config) -> bool:
    from trustroute.harness.study import context as context_module

    return config not in context_module._CONTEXTS
