"""`keyword_names`: an InputError as the Python API says it, its command-line flags named as the
keyword arguments."""

from __future__ import annotations

from trustroute.core.errors import InputError, keyword_names


def test_flags_become_keyword_names_and_paths_stay():
    said = keyword_names(InputError("--initial-trust", "", "unknown --belief-source in /a/--b and a--b",
                                    "pass an existing town file with --town, or omit --horizon"))
    assert str(said) == ("initial_trust: unknown belief_source in /a/--b and a--b (fix: pass an "
                         "existing town file as town, or omit horizon)")
    assert isinstance(said, InputError)
