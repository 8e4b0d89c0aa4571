import numpy as np

from trustroute.core.wording import counted, shown_value


def test_one_is_singular_and_every_other_count_plural():
    assert [counted(n, "file") for n in (0, 1, 2)] == ["0 files", "1 file", "2 files"]
    assert counted(1, "person", "people") == "1 person" and counted(3, "person", "people") == "3 people"


def test_a_refused_value_shows_a_string_quoted_and_a_number_bare():
    values = ("5", 5, 2.5, None, True, ["a", 1])
    assert [shown_value(v) for v in values] == ["'5'", "5", "2.5", "None", "True", "['a', 1]"]
    assert shown_value(np.int64(9)) == "9" and shown_value(np.float64(0.5)) == "0.5"
    # a long value is cut, the cut marked: a string cut short never reads as a whole one
    assert shown_value("x" * 50) == "'" + "x" * 36 + "..." and len(shown_value("x" * 50)) == 40
    assert shown_value(list(range(30)), 20) == "[0, 1, 2, 3, 4, 5..."
    assert shown_value("x" * 38) == repr("x" * 38)  # 40 characters: not cut


def test_a_refused_value_is_one_line_and_a_numpy_string_is_quoted_as_a_string():
    assert shown_value(np.array([[1, 2], [3, 4]])) == "[[1 2] [3 4]]"
    assert shown_value(np.str_("5")) == "'5'"
    assert shown_value(b"ab\ncd") == "b'ab\\ncd'" and shown_value("a\nb") == "'a\\nb'"
