"""The field tables and their validator: kinds, required keys and defaults, messages, places; and the
tables of the four input formats (what each loader accepts)."""

from __future__ import annotations

import math
import re
from typing import TypedDict

import pytest

from trustroute.core.errors import InputError
from trustroute.core.fields import (
    PROBABILITY,
    Field,
    Flag,
    Integer,
    ListOf,
    Number,
    OneOf,
    Table,
    Text,
    check_fields,
    check_value,
    field_table,
    holds_bool,
    is_number,
    keys,
)


def problem_of(value: object, kind) -> str | None:
    rejection = kind.reject(value)
    return None if rejection is None else rejection.problem


@pytest.mark.parametrize("kind", [Integer(), Number(), PROBABILITY, Number(finite=False)])
@pytest.mark.parametrize("value", [True, False])
def test_no_number_kind_accepts_a_bool(kind, value):
    assert problem_of(value, kind) is not None


def test_number_kinds():
    assert problem_of(3, Integer(minimum=1, maximum=5)) is None
    assert problem_of(6, Integer(minimum=1, maximum=5)) == "expected an integer from 1 to 5, got 6"
    assert problem_of(3.0, Integer()) is not None
    # a string is shown as one: `seed = "3"` in a TOML file is not 3
    assert problem_of("3", Integer(minimum=1, maximum=5)) == "expected an integer from 1 to 5, got '3'"
    assert problem_of("9" * 60, Integer()).endswith("got '" + "9" * 36 + "...")
    assert problem_of(False, Integer(false_allowed=True)) is None
    assert problem_of(True, Integer(false_allowed=True)) is not None
    assert problem_of(math.inf, Number()) is not None
    assert problem_of(math.inf, Number(finite=False)) is None
    assert problem_of(math.nan, Number(finite=False)) is not None
    assert problem_of(0.0, Number(minimum=0.0, open_below=True)) == "0.0 is not a number in (0, inf)"
    assert problem_of(math.inf, Number(minimum=1.0)) == "inf is not a finite number"
    # an infinite end of a finite number's interval is open: inf is not among the values taken
    assert (Number(minimum=1.0).interval(), Number(finite=False).interval()) == ("[1, inf)", "[-inf, inf]")
    assert problem_of(1.0, Number(minimum=0.0, maximum=1.0, open_above=True)) is not None
    assert problem_of(0.5, PROBABILITY) is None and problem_of(1.5, PROBABILITY) is not None
    assert is_number(2) and is_number(0.5) and not is_number(True) and not is_number(math.nan)
    assert holds_bool([[0.5, True]]) and not holds_bool([[0.5, 1]])


def test_text_choice_flag_and_lists():
    assert problem_of("", Text()) == "expected a non-empty string, got ''"
    assert problem_of("", Text(nonempty=False)) is None
    assert problem_of("a-b", Text(pattern=re.compile(r"\w+"))) is not None
    assert problem_of("abc", Text(max_length=2)) is not None
    assert problem_of(1, OneOf(choices=(True, 1))) is None
    assert problem_of(True, OneOf(choices=(1,))) == "unknown value True"  # bool is not 1
    assert problem_of(5, OneOf(choices=("5",))) == "unknown value 5"
    assert problem_of("y" * 60, OneOf(choices=("5",))) == "unknown value '" + "y" * 36 + "..."
    assert problem_of(1, Flag()) is not None and problem_of(False, Flag()) is None
    strings = ListOf(item=Text(), min_items=1, distinct=True)
    assert problem_of([], strings) == "expected a non-empty list of strings, got []"
    assert problem_of(["a", 1], strings) is not None
    assert strings.reject(["a", "a"]) == ("lists the same entry twice", "list each entry once", "")
    assert problem_of([1, 2, 2], ListOf(item=Integer(), increasing=True)) is not None
    assert problem_of([[1], [1]], ListOf(distinct=True)) == "lists the same entry twice"  # unhashable items
    assert problem_of([1, 2], ListOf(max_items=1)) is not None
    long = problem_of(list(range(100)), ListOf(max_items=1))
    assert long == ("expected a list of values, got "
                    "[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16...")  # 60 characters


FIELDS = (
    Field(key="count", kind=Integer(minimum=1, maximum=9), required=True, fix="write count = 3",
          missing_fix="add count = 3"),
    Field(key="mode", kind=OneOf(choices=("fast", "slow"), noun="mode"), default="fast"),
    Field(key="weights", kind=Table(values=PROBABILITY), default={}, problem="expected an object",
          fix="write {name: probability}"),
    Field(key="label", kind=Text(), problem=lambda seen: f"{seen.owner}: label {seen.value!r} is not text",
          fix="write label = \"x\""),
)


def error(data: dict, place="", owner="") -> InputError:
    with pytest.raises(InputError) as info:
        check_fields(data, FIELDS, "f.toml", "test table", place, owner)
    return info.value


def test_values_and_defaults():
    assert keys(FIELDS) == ("count", "mode", "weights", "label")
    assert check_fields({"count": 2}, FIELDS, "f.toml", "test table") == {
        "count": 2, "mode": "fast", "weights": {}, "label": None}


def test_unknown_then_missing_then_values_in_table_order():
    bad = error({"cuont": 2, "mode": "x"}, "t")
    assert (bad.place, bad.problem) == ("t.cuont", "unknown key 'cuont' in the test table")
    assert bad.fix == ("write count, the closest key, or one of count, mode, weights, label (a misspelt key "
                       "would be ignored otherwise)")
    assert error({"zzz": 1}).fix == ("use only count, mode, weights, label (a misspelt key would be ignored "
                                     "otherwise)")
    bad = error({"mode": "x"}, "t")
    assert (bad.place, bad.problem, bad.fix) == ("t.count", "missing key 'count'", "add count = 3")
    bad = error({"count": 0, "mode": "x"})
    assert (bad.place, bad.problem, bad.fix) == ("count", "expected an integer from 1 to 9, got 0",
                                                 "write count = 3")


def test_messages_kind_field_and_hint():
    bad = error({"count": 1, "mode": "medium"})
    assert (bad.problem, bad.fix) == ("unknown mode 'medium'", "use one of fast, slow")
    bad = error({"count": 1, "weights": [0.5]})
    assert (bad.place, bad.problem, bad.fix) == ("weights", "expected an object", "write {name: probability}")
    bad = error({"count": 1, "weights": {"a": 0.5, "b": True}})
    assert (bad.place, bad.problem, bad.fix) == ("weights.b", "True is not a probability in [0, 1]",
                                                 "give a number in [0, 1]")
    bad = error({"count": 1, "label": 3}, owner="atom 'x'")
    assert bad.problem == "atom 'x': label 3 is not text"


def test_a_place_function_places_every_key():
    bad = error({"count": 1, "extra": 1}, place=lambda key: f"line 9 ({key})")
    assert bad.place == "line 9 (extra)"
    bad = error({}, place=lambda key: f"line 9 ({key})")
    assert bad.place == "line 9 (count)"


def test_check_value_gives_its_own_messages():
    assert check_value([1.0, 2.0], ListOf(item=Number(), min_items=2, max_items=2), "f", "xy") == [1.0, 2.0]
    with pytest.raises(InputError) as info:
        check_value([1.0, True], ListOf(item=Number(), min_items=2, max_items=2), "f", "xy",
                    "not two finite numbers", "write [x, y]")
    assert (info.value.place, info.value.problem, info.value.fix) == ("xy", "not two finite numbers",
                                                                     "write [x, y]")


class CountValues(TypedDict):
    count: int
    mode: str


def test_a_field_table_checks_into_its_typed_dict_of_values():
    table = field_table(CountValues, *FIELDS[:2])
    assert table == FIELDS[:2] and keys(table) == ("count", "mode")
    assert check_fields({"count": 2}, table, "f.toml", "test table") == {"count": 2, "mode": "fast"}
    with pytest.raises(TypeError, match="CountValues has keys"):
        field_table(CountValues, *FIELDS)  # two fields the TypedDict does not name
    with pytest.raises(TypeError, match="CountValues has keys"):
        field_table(CountValues, FIELDS[0])  # a key of the TypedDict without its field


def test_every_format_exposes_its_accepted_keys():
    from trustroute.harness.study import config
    from trustroute.networks import town
    from trustroute.participants import driver_model, driver_population
    from trustroute.policies.logic import spec

    assert town.TOWN_KEYS == keys(town.FIELDS) == ("junctions", "roads", "incidents", "source",
                                                          "one_way", "geometry", "sumo_net", "turns")
    assert driver_model.DRIVER_MODEL_KEYS == keys(driver_model.FIELDS)
    assert "trust_free_takeover_probability" in driver_model.DRIVER_MODEL_KEYS
    assert driver_population.POPULATION_KEYS == ("format", "version", "source", "types")
    assert driver_population.TYPE_KEYS == ("name", "weight", "model", "model_file")
    assert spec.TOP_LEVEL_KEYS == ("name", "start", "formula", "states", "beliefs", "trust_states",
                                   "type_beliefs")
    assert keys(spec.BELIEF_FIELDS) == ("coeffs", "offset")
    assert keys(spec.TRUST_STATE_FIELDS) == ("roads", "trust")
    assert keys(spec.TYPE_BELIEF_FIELDS) == ("types", "above")
    assert config.TABLES == ("study", "population", "drivers", "questionnaires", "live")
    assert config.DRIVERS_KEYS == ("population",)
    assert len(config.STUDY_KEYS) == 21 and config.STUDY_KEYS[:5] == ("participants", "seed", "engine",
                                                                     "specs", "conditions")
