"""The one error type for bad input anywhere in trustroute.

Every loader raises `InputError` naming the file, the place in it and the fix;
the CLI turns it into a single line on stderr and exit code 2.
"""

from __future__ import annotations


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


def _clean(text: str, limit: int = 200) -> str:
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))
    return text if len(text) <= limit else text[: limit - 3] + "..."
