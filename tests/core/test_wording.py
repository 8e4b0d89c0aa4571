from trustroute.core.wording import counted


def test_one_is_singular_and_every_other_count_plural():
    assert [counted(n, "file") for n in (0, 1, 2)] == ["0 files", "1 file", "2 files"]
    assert counted(1, "person", "people") == "1 person" and counted(3, "person", "people") == "3 people"
