"""The one error type for bad input anywhere in trustroute.

Every loader raises `InputError` naming the file, the place in it and the fix;
the CLI turns it into a single line on stderr and exit code 2.
"""

from __future__ import annotations

import re


class InputError(Exception):
    """Bad user input: a malformed file, a missing binary, a mismatched policy."""

    def __init__(self, source: str, place: str, problem: str, fix: str) -> None:
        self.source = str(source)
        self.place = place
        self.problem = problem
        self.fix = fix
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The message on one line: control characters escaped, each part capped in length (a file
        name or key taken from bad input must not spill over lines or screens)."""
        where = f"{_clean(self.source)}: {_clean(self.place)}" if self.place else _clean(self.source)
        return f"{where}: {_clean(self.problem, 400)} (fix: {_clean(self.fix, 300)})"


# A command-line flag in a message ("--initial-trust"), not a dash inside a word or a path.
_FLAG = re.compile(r"(?<![\w/.-])--([a-z][a-z0-9]*(?:-[a-z0-9]+)*)")
_WITH_FLAG = re.compile(r"\bwith (--[a-z])")
# A trustroute command a message tells the reader to type ("trustroute town roads TOWN --street
# NAME"): its subcommand words, then its placeholders and flags; typed as it is, so its flags stay.
_COMMAND = re.compile(r"(\btrustroute(?: [a-z][a-z-]*)+(?: (?:[A-Z][A-Z_.]*|--[a-z][a-z0-9-]*))*)")


def keyword_names(error: InputError) -> InputError:
    """`error` as the Python API says it: the command-line flags it names (`--initial-trust`), the
    CLI's words, become the API's keyword arguments of the same names (`initial_trust`)."""
    def in_words(text: str) -> str:
        text = _WITH_FLAG.sub(r"as \1", text)   # "a file with --town": "a file as town"
        return _FLAG.sub(lambda flag: flag.group(1).replace("-", "_"), text)

    def outside_commands(text: str) -> str:
        # re.split with one group: the odd parts are the commands
        parts = _COMMAND.split(text)
        return "".join(in_words(part) if index % 2 == 0 else part for index, part in enumerate(parts))

    def keyword(text: str) -> str:
        # a command, quoted in backticks ("run `trustroute study CONFIG --out DIR`") or not, is typed
        # as it is: its flags stay; the text outside the quotes (the even parts) is said as keywords
        parts = text.split("`")
        return "`".join(outside_commands(part) if index % 2 == 0 else part
                        for index, part in enumerate(parts))

    said = InputError.__new__(type(error))
    said.__dict__.update(error.__dict__)
    said.source, said.place = keyword(error.source), keyword(error.place)
    said.problem, said.fix = keyword(error.problem), keyword(error.fix)
    Exception.__init__(said, said.one_line())
    return said


def _clean(text: str, limit: int = 200) -> str:
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))
    return text if len(text) <= limit else text[: limit - 3] + "..."
