"""The analysis depends on the participants' data, not on their numbers or the tables' row order:
the tables of an exported package (participants renamed to random codes, rows sorted by code) give
the study's own analysis bit for bit, intervals and last digits included."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from tests.cli import run_cli
from trustroute.analysis.study.canonical import canonical_tables, participant_ranks
from trustroute.core.dataset import EPISODES_FILE, MANIFEST_FILE, ROADS_FILE, STUDY_FILE


def analysis_json(capsys, study) -> dict:
    code, out, err = run_cli(capsys, "analyze", str(study), "--json")
    assert code == 0, err
    result = json.loads(out)
    result.pop("study_dir")
    result.pop("paths")
    return result


@pytest.mark.slow
def test_the_tables_of_an_exported_package_give_the_studys_analysis_bit_for_bit(model_study, tmp_path,
                                                                                capsys):
    copied = shutil.copytree(model_study, tmp_path / "study")   # an export writes its key into the study
    code, _, err = run_cli(capsys, "export", str(copied), "--out", str(tmp_path / "package"))
    assert code == 0, err
    # the study as a reviewer holds it: its manifest and inputs, and the package's tables
    reviewed = tmp_path / "reviewed"
    reviewed.mkdir()
    for name in (MANIFEST_FILE, STUDY_FILE):
        shutil.copy(model_study / name, reviewed / name)
    shutil.copytree(model_study / "inputs", reviewed / "inputs")
    for name in (EPISODES_FILE, ROADS_FILE):
        shutil.copy(tmp_path / "package" / "tables" / name, reviewed / name)
    renamed = pd.read_parquet(reviewed / EPISODES_FILE)
    own = pd.read_parquet(model_study / EPISODES_FILE)
    assert set(renamed["participant"]).isdisjoint(own["participant"])   # the codes are 100-999
    assert list(renamed["mean_reported_trust"]) != list(own["mean_reported_trust"])   # another order
    study, package = analysis_json(capsys, model_study), analysis_json(capsys, reviewed)
    assert study["cells"][0]["trust_ci_low"] is not None and study["paired"]
    assert package == study


def test_ranks_follow_the_data_whatever_the_names_and_order(model_study):
    episodes = pd.read_parquet(model_study / EPISODES_FILE)
    roads = pd.read_parquet(model_study / ROADS_FILE)
    ranks = participant_ranks(episodes, roads)
    assert sorted(ranks.values()) == list(range(episodes["participant"].nunique()))
    rng = np.random.default_rng(7)
    codes = dict(zip(sorted(ranks), rng.permutation(900)[: len(ranks)] + 100, strict=True))
    ids = {e: e.replace(f"p{p:05d}", f"p{codes[p]:03d}")
           for e, p in zip(episodes["episode_id"], episodes["participant"], strict=True)}
    shuffled = episodes.assign(participant=episodes["participant"].map(codes),
                               episode_id=episodes["episode_id"].map(ids),
                               seed=0, wall_seconds=1.0).sample(frac=1.0, random_state=1)
    renamed_roads = roads.assign(episode_id=roads["episode_id"].map(ids)).sample(frac=1.0, random_state=2)
    # the episodes' roads in their own order, wherever each episode's rows lie
    renamed_roads = renamed_roads.sort_values(["episode_id", "index"], kind="stable")
    assert participant_ranks(shuffled, renamed_roads) == {codes[p]: r for p, r in ranks.items()}


def test_a_table_of_episodes_is_renumbered_as_the_episodes_are(model_study):
    """A table of one row per episode, in an order of its own (not the episodes'), comes back in rank
    order with each row's participant the rank of its own episode, each participant's rows in the
    table's order."""
    columns = ["episode_id", "participant", "spec", "condition"]
    episodes = pd.read_parquet(model_study / EPISODES_FILE).sample(frac=1.0, random_state=3)
    roads = pd.read_parquet(model_study / ROADS_FILE)
    per_episode = episodes[columns].sample(frac=1.0, random_state=4)
    assert list(per_episode["episode_id"]) != list(episodes["episode_id"])
    ranked, _, rank_of_episode, (table,) = canonical_tables(episodes, roads, per_episode)
    assert sorted(set(ranked["participant"])) == list(range(episodes["participant"].nunique()))
    own = dict(zip(episodes["episode_id"], episodes["participant"], strict=True))
    assert any(rank != own[e] for e, rank in rank_of_episode.items())   # renumbering moves someone
    by_rank = sorted(per_episode["episode_id"], key=rank_of_episode.__getitem__)   # stable
    assert list(table["episode_id"]) == by_rank
    assert list(table["participant"]) == [rank_of_episode[e] for e in by_rank]
    expected = ranked[columns].set_index("episode_id").loc[by_rank].reset_index()
    assert table.reset_index(drop=True).equals(expected)
