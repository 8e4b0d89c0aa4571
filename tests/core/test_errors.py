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


def test_a_command_to_type_keeps_its_flags_quoted_or_not():
    said = keyword_names(InputError(
        "spec.toml", "", "no road is on a street named 'X' (--street)",
        "use a street name the town gives (trustroute town roads TOWN --street NAME), or re-run "
        "trustroute synth --population for this one, or with --town run `trustroute net build --help`"))
    assert str(said) == (
        "spec.toml: no road is on a street named 'X' (street) (fix: use a street name the town gives "
        "(trustroute town roads TOWN --street NAME), or re-run trustroute synth --population for this "
        "one, or as town run `trustroute net build --help`)")
