"""A study's design as its data show it: the packaged real study (21 participants, no seed, one
fixed session order) is described as it was run, compared with the paper, and its order table says
that position is confounded with the cell; a Williams study keeps its order tests."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from trustroute.analysis.study.design import fixed_order, study_participants
from trustroute.analysis.study.display import order_test_line
from trustroute.analysis.study.order import order_tables
from trustroute.analysis.study.paper_comparison import is_paper_comparable
from trustroute.analysis.study.report import study_lines

REAL_STUDY = Path(__file__).resolve().parents[3] / "analysis" / "data" / "real_study" / "study"
SESSIONS = [["phi1", "aware"], ["phi1", "free"], ["phi2", "aware"], ["phi2", "free"]]


def _real() -> tuple[dict, pd.DataFrame]:
    manifest = json.loads((REAL_STUDY / "manifest.json").read_text())
    return manifest, pd.read_parquet(REAL_STUDY / "episodes.parquet")


def test_the_real_study_is_described_as_it_was_run_and_compared_with_the_paper():
    manifest, episodes = _real()
    assert "participants" not in manifest["config"] and "seed" not in manifest["config"]
    assert episodes["participant"].nunique() == 21
    assert study_participants(manifest, episodes) == 21
    line = study_lines(manifest, episodes)[0]
    assert line.startswith("carla-real-study: 21 participants x 2 specs x 2 conditions"), line
    assert "None" not in line and "no seed" in line and "Latin square" not in line
    assert not any("None" in later for later in study_lines(manifest, episodes)[1:3])
    provenance = study_lines(manifest, episodes)[2]
    assert "episodes imported from trust_aware_hrc_carla_sim" in provenance
    # the revision is trustroute's (the importer's), not a commit of the authors' repository
    assert f", trustroute's git revision {manifest['git_revision']}, created" in provenance, provenance
    assert "one fixed order (phi1 aware, phi1 free, phi2 aware, phi2 free)" in line
    comparable, note = is_paper_comparable(manifest, episodes)
    assert comparable and note == ""


def test_a_fixed_order_has_no_order_tests_and_says_why():
    _, episodes = _real()
    order, tests, _ = order_tables(episodes, "satisfied")
    assert order["position"].tolist() == [1, 2, 3, 4]
    for position, row in zip(range(4), order.itertuples(), strict=True):
        at = episodes[episodes["position"] == position]
        assert (row.n, row.satisfied) == (len(at), int(at["satisfied"].sum()))
    assert tests["fixed_order"] == SESSIONS
    assert tests["cochran_q_p"] is None and tests["friedman_p"] is None
    line = order_test_line(tests)
    assert "confounded" in line and "Cochran's Q p =" not in line


def _williams(participants: int) -> pd.DataFrame:
    """Participants in the rows of the 4-cell Williams square (0 1 3 2, 1 2 0 3, 2 3 1 0, 3 0 2 1)."""
    rows = [(0, 1, 3, 2), (1, 2, 0, 3), (2, 3, 1, 0), (3, 0, 2, 1)]
    cells = [tuple(cell) for cell in SESSIONS]
    return pd.DataFrame([
        {"participant": p, "position": position, "spec": cells[cell][0], "condition": cells[cell][1],
         "satisfied": (p + cell) % 3 != 0, "mean_reported_trust": float(1 + (p * 5 + cell * 3) % 7)}
        for p in range(participants) for position, cell in enumerate(rows[p % 4])])


def test_a_counterbalanced_study_keeps_its_order_tests():
    episodes = _williams(8)
    assert fixed_order(episodes) is None
    assert fixed_order(_williams(1)) is None          # one participant shows no common order
    assert fixed_order(episodes[episodes["participant"] % 4 == 1]) == [
        ("phi1", "free"), ("phi2", "aware"), ("phi1", "aware"), ("phi2", "free")]
    _, tests, _ = order_tables(episodes, "satisfied")
    assert "fixed_order" not in tests and tests["participants"] == 8
    assert tests["cochran_q_p"] is not None and tests["friedman_p"] is not None
    manifest = {"study": "s", "engine": "model", "config": {"participants": 8, "seed": 3, "specs": [1, 2],
                                                            "conditions": [1, 2]}}
    assert "seed 3, counterbalanced by a Williams Latin square" in study_lines(manifest, episodes)[0]


def test_friedman_names_the_participants_it_reads_when_fewer_than_cochrans():
    """Cochran's Q reads every participant who drove every position, Friedman only those with a
    trust report at every position: the line says how many Friedman's test rests on."""
    from scipy import stats

    episodes = _williams(8)
    episodes.loc[(episodes["participant"] == 5) & (episodes["position"] == 2), "mean_reported_trust"] = None
    _, tests, _ = order_tables(episodes, "satisfied")
    assert tests["participants"] == 8 and tests["friedman_participants"] == 7
    trust = episodes[episodes["participant"] != 5].pivot_table(
        index="participant", columns="position", values="mean_reported_trust").to_numpy()
    assert tests["friedman_p"] == stats.friedmanchisquare(*trust.T).pvalue
    line = order_test_line(tests)
    assert "within 8 participants" in line
    assert "(reported trust, within the 7 with a report at every position)" in line
    _, complete, _ = order_tables(_williams(8), "satisfied")
    assert "with a report" not in order_test_line(complete)


def _two_cells(participants: int) -> pd.DataFrame:
    """Participants alternating the orders (aware, free) and (free, aware) of one spec."""
    return pd.DataFrame([
        {"participant": p, "position": position, "spec": "phi1", "condition": condition,
         "satisfied": (p + position) % 3 != 0, "mean_reported_trust": float(1 + (p * 5 + position * 3) % 7)}
        for p in range(participants)
        for position, condition in enumerate(("aware", "free") if p % 2 == 0 else ("free", "aware"))])


def test_a_missing_order_test_says_why():
    """A p-value shown as "-" carries its reason, in the analysis' words for missing estimates."""
    _, two, _ = order_tables(_two_cells(6), "satisfied")
    assert two["cochran_q_p"] is not None and two["friedman_p"] is None
    assert two["cochran_q_note"] == ""
    assert two["friedman_note"] == "2 positions: Friedman's test needs 3 or more"
    assert order_test_line(two).endswith(
        "(satisfaction), Friedman p = - (reported trust; 2 positions: Friedman's test needs 3 or more).")
    _, one, _ = order_tables(_williams(1), "satisfied")
    assert order_test_line(one) == (
        "Across positions within 1 participant: no Cochran's Q or Friedman p (too few observations: "
        "fewer than 2 participants drove every position).")
    same = _williams(8).assign(satisfied=True, mean_reported_trust=5.0)
    _, tied, _ = order_tables(same, "satisfied")
    line = order_test_line(tied)
    assert "Cochran's Q p = - (satisfaction; no variation: every episode's outcome the same)" in line
    assert "Friedman p = - (reported trust; no variation: every mean reported trust the same)" in line
    _, single, _ = order_tables(_two_cells(4)[lambda e: e["position"] == 0], "satisfied")
    assert single["cochran_q_note"] == single["friedman_note"] == "one position: no order to compare"


def test_the_terminal_prints_the_order_tests_under_the_order_table(model_study):
    """As the report does: the line belongs to the table by position, not to the last table."""
    from trustroute.analysis.study.analysis import study_analysis
    from trustroute.analysis.study.display import format_table

    analysis = study_analysis(model_study)
    lines = format_table(analysis).splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("Order effects"))
    after = lines[start + 3 + len(analysis.order):]
    assert after[0].startswith("Across positions within 12 participants: Cochran's Q p = "), after[:2]


def test_a_live_study_counts_the_participants_with_data_not_those_planned():
    """A live study's config counts the participants planned; one who withdrew has their data
    deleted and one who declined has none: the design line and the paper's comparison count the
    participants in the episodes, with the number planned beside them."""
    config = {"participants": 21, "specs": ["phi1.toml", "phi2.toml"], "conditions": ["aware", "free"],
              "seed": 4}
    manifest = {"study": "live-study", "engine": "live", "config_path": "live.toml", "config_hash": "0" * 64,
                "config": config}
    episodes = pd.DataFrame([{"participant": p, "position": i, "spec": s, "condition": c}
                             for p in range(19) for i, (s, c) in enumerate(SESSIONS)])
    assert study_participants(manifest, episodes) == 19
    line = study_lines(manifest, episodes)[0]
    assert line.startswith("live-study: 19 participants with data (of 21 planned) x 2 specs"), line
    assert "19 participants, the paper had 21" in is_paper_comparable(manifest, episodes)[1]
    one = episodes[episodes["participant"] == episodes["participant"].iloc[0]]
    assert "1 participant, the paper had 21" in is_paper_comparable(manifest, one)[1]
    simulated = {**manifest, "engine": "model"}
    assert study_participants(simulated, episodes) == 21   # a simulated study runs every planned one


def test_a_study_of_one_spec_is_described_in_the_singular():
    """The design line counts in the singular for one, and the models' title does not speak of two
    specs on a study of one."""
    from trustroute.analysis.study.display import TABLE_TITLES

    config = {"participants": 1, "specs": ["drt.toml"], "conditions": ["aware", "free"], "seed": 3}
    manifest = {"study": "drt", "engine": "sumo", "config_path": "drt.toml", "config_hash": "0" * 64,
                "config": config}
    episodes = pd.DataFrame([{"participant": 0, "position": i, "spec": "drt", "condition": c}
                             for i, c in enumerate(["aware", "free"])])
    line = study_lines(manifest, episodes)[0]
    assert line.startswith("drt: 1 participant x 1 spec x 2 conditions, sumo engine"), line
    assert "both" not in TABLE_TITLES["repeated"]
