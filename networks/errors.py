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
        where = f"{self.source}: {self.place}" if self.place else self.source
        return f"{where}: {self.problem} (fix: {self.fix})"
