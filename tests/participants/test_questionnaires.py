"""The packaged questionnaires, Likert files, the study config's placement of them, and answers."""

from __future__ import annotations

import pytest

from tests.questionnaire_files import COMFORT
from trustroute.analysis.study.questionnaires import cronbach_alpha
from trustroute.core.errors import InputError
from trustroute.participants.questionnaires import (
    JIAN,
    NASA_TLX,
    PLACEMENTS,
    load_questionnaire,
    questionnaire_plan,
)


def test_the_packaged_scales():
    assert len(JIAN.items) == 12 and (JIAN.minimum, JIAN.maximum) == (1, 7)
    assert [item.reversed for item in JIAN.items] == [True] * 5 + [False] * 7
    everything_high = {item.id: 7 for item in JIAN.items}
    assert JIAN.score(everything_high) == pytest.approx((5 * 1 + 7 * 7) / 12)   # distrust items turned
    assert len(NASA_TLX.items) == 6 and NASA_TLX.score({i.id: 50 for i in NASA_TLX.items}) == 50
    with pytest.raises(ValueError, match="missing: j12"):
        JIAN.check({item.id: 4 for item in JIAN.items[:11]})
    with pytest.raises(ValueError, match="not on the scale"):
        NASA_TLX.check({item.id: 52 for item in NASA_TLX.items})   # steps of 5
    with pytest.raises(ValueError, match="not on the scale"):
        JIAN.check({item.id: True for item in JIAN.items})
    assert NASA_TLX.check({item.id: 55 for item in NASA_TLX.items})["mental"] == 55.0


def test_an_answer_is_a_point_of_the_scale_exactly():
    """The range is checked before the steps (a huge number is refused, not an overflow), and the
    steps exactly: a number a hair off a point is no point of the scale."""
    everything = {item.id: 0 for item in NASA_TLX.items}
    for value in (10**400, -(10**400), 50.0000000001, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="not on the scale"):
            NASA_TLX.check(everything | {"mental": value})
    assert NASA_TLX.check(everything | {"mental": 55.0, "effort": 100})["effort"] == 100.0


def test_a_scale_in_decimal_steps(tmp_path):
    """A step of 0.1 is one tenth: 0.3 is the scale's third point (in binary floating point
    0.3 / 0.1 is not 3), and 0.25 is no point of it."""
    (tmp_path / "tenths.toml").write_text(COMFORT.replace("max = 5", "max = 0.3, step = 0.1")
                                          .replace("min = 1", "min = 0"))
    tenths = load_questionnaire(tmp_path / "tenths.toml", "study.toml")
    assert tenths.check({"c1": 0.3, "c2": 0.1}) == {"c1": 0.3, "c2": 0.1}
    with pytest.raises(ValueError, match="not on the scale"):
        tenths.check({"c1": 0.25, "c2": 0.1})


def test_a_likert_file_and_the_config_table(tmp_path):
    (tmp_path / "comfort.toml").write_text(COMFORT)
    comfort = load_questionnaire(tmp_path / "comfort.toml", "study.toml")
    assert [item.reversed for item in comfort.items] == [False, True]
    assert comfort.score({"c1": 5, "c2": 5}) == 3
    table = {"before": ["nasa_tlx"], "after_each_trial": ["jian", "comfort.toml"]}
    plan = questionnaire_plan(table, tmp_path, "study.toml")
    assert [q.name for q in plan["after_each_trial"]] == ["jian", "comfort"] and plan["end"] == ()
    for table, where in (({"during": ["jian"]}, "questionnaires.during"),
                         ({"end": "jian"}, "questionnaires.end"),
                         ({"end": ["jian", "jian"]}, "questionnaires.end"),
                         ({"end": ["missing.toml"]}, "missing.toml")):
        with pytest.raises(InputError, match=where):
            questionnaire_plan(table, tmp_path, "study.toml")
    (tmp_path / "bad.toml").write_text(COMFORT.replace("max = 5", "max = 0"))
    with pytest.raises(InputError, match="questionnaire.scale"):
        load_questionnaire(tmp_path / "bad.toml", "study.toml")


def test_cronbach_alpha():
    import numpy as np

    items = np.array([[1, 2, 2], [3, 3, 4], [5, 4, 5], [2, 2, 1]], dtype=float)
    # the same alpha through the item covariances: k c / (v + (k - 1) c), v the mean item variance
    # and c the mean covariance between two items
    covariance, k = np.cov(items, rowvar=False), 3
    v, c = np.mean(np.diag(covariance)), covariance[~np.eye(k, dtype=bool)].mean()
    assert cronbach_alpha(items) == pytest.approx(k * c / (v + (k - 1) * c))
    assert cronbach_alpha(np.ones((4, 3))) is None and cronbach_alpha(items[:1]) is None


def test_a_misspelt_key_of_a_questionnaire_or_its_placement_names_the_closest(tmp_path):
    (tmp_path / "typo.toml").write_text(COMFORT.replace("title =", "titel ="))
    with pytest.raises(InputError) as error:
        load_questionnaire(tmp_path / "typo.toml", "study.toml")
    assert error.value.place == "questionnaire.titel"
    assert error.value.fix.startswith("write title, the closest key, or one of name, title, ")
    with pytest.raises(InputError) as error:
        questionnaire_plan({"ends": ["jian"]}, tmp_path, "study.toml")
    assert error.value.place == "questionnaires.ends"
    assert error.value.fix.startswith("write end, the closest key, or one of before, after_each_trial, end")


def test_the_packaged_instructions_follow_where_the_questionnaire_is_asked(tmp_path):
    """Before any drive there is no drive just completed; at the end, all of them are rated."""
    for questionnaire in (JIAN, NASA_TLX):
        before, after, end = (questionnaire.to_client(p)["instructions"] for p in PLACEMENTS)
        assert "just" in after and "just" not in before and "just" not in end
        assert len({before, after, end}) == 3
    after_trial = NASA_TLX.to_client("after_each_trial")["instructions"]
    assert after_trial == "Rate the drive you just completed on each scale."
    (tmp_path / "comfort.toml").write_text(COMFORT)
    comfort = load_questionnaire(tmp_path / "comfort.toml", "study.toml")   # a file's: as written, anywhere
    assert {comfort.to_client(p)["instructions"] for p in PLACEMENTS} == {"How much do you agree?"}


def test_the_workload_items_speak_of_the_drive_that_is_rated():
    """NASA-TLX's items asked before any drive ask what a drive is expected to bring, after a trial
    of the drive just completed, at the end of the session's drives: no item asks how a drive 'was'
    before there was one, under instructions asking for what is expected."""
    before, after, end = ([item["text"] for item in NASA_TLX.to_client(p)["items"]] for p in PLACEMENTS)
    assert after[0] == "Mental demand: how mentally demanding was the drive?"
    assert all("expect" in text and " was " not in text and " were " not in text for text in before), before
    assert all("the drive?" not in text for text in end) and "were the drives" in end[0], end
    assert len(set(before)) == len(set(end)) == 6
    # the ids, and so the answers' rows and scores, are the same wherever it is asked
    assert {tuple(i["id"] for i in NASA_TLX.to_client(p)["items"]) for p in PLACEMENTS} == {
        tuple(item.id for item in NASA_TLX.items)}
