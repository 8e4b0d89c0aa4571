"""Range and finiteness checks of command-line options, done before any work starts.

click's FloatRange lets NaN through (every comparison with NaN is false), and an unbounded
integer such as `--horizon 10**18` would start work that can never finish: every numeric option is
`Checked` by its range in trustroute/core/ranges.py instead (the one the API checks, where the API
takes the option too). A bad value is one line in the project's wording, exit code 2.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import click

from trustroute.core import ranges
from trustroute.core.fields import Integer, Number
from trustroute.core.ranges import UNBOUNDED, OptionRange


class UsageFix(click.UsageError):
    """A usage error of a command's own (options that exclude each other, a missing argument)
    with the fix its one line names: exit code 2 under click's own runner too."""

    def __init__(self, message: str, fix: str, ctx: click.Context | None = None) -> None:
        super().__init__(message, ctx)
        self.fix = fix


class Checked(click.ParamType):
    """A numeric option: its value is parsed as the range's kind and checked by the range itself
    (trustroute/core/ranges.py `OptionRange`), the check the API makes where it takes the option too,
    so every door refuses it with the same words (an InputError: one line, exit code 2)."""

    def __init__(self, accepted: OptionRange) -> None:
        self.accepted = accepted
        self.name = "integer" if isinstance(accepted.kind, Integer) else "number"

    def convert(self, value, param, ctx):
        if isinstance(value, str):
            parse = int if isinstance(self.accepted.kind, Integer) else float
            try:
                value = parse(value)
            except ValueError:
                pass   # refused by the range, which names the text given
        return self.accepted.check(value)

    def get_metavar(self, param: click.Parameter, ctx: click.Context) -> str:
        return range_metavar(self.accepted)


def range_metavar(accepted: OptionRange) -> str:
    """The kind and range of an option, as --help lists it (`INTEGER 1..1000`, `NUMBER (0, 1]`)."""
    kind = accepted.kind
    if isinstance(kind, Integer):
        top = "" if kind.maximum == UNBOUNDED.maximum else str(kind.maximum)
        return f"INTEGER {kind.minimum}..{top}"
    assert isinstance(kind, Number)
    return f"NUMBER {kind.interval()}"


SEED = Checked(ranges.SEED)         # an episode's, a plan's, a population's draws
WORKERS = Checked(ranges.WORKERS)   # a study's worker processes


@dataclass(frozen=True)
class CommandStart:
    """When `trustroute` began (time.perf_counter()): the click context's object."""

    started: float

    @classmethod
    def now(cls) -> CommandStart:
        """The process's start: now less its age (the interpreter's start-up and first imports)."""
        return cls(time.perf_counter() - process_age())


def process_age() -> float:
    """Seconds since this process started, from /proc on Linux; 0 where that cannot be read."""
    import os

    try:
        with open("/proc/self/stat") as stat, open("/proc/uptime") as uptime:
            start_ticks = int(stat.read().rsplit(")", 1)[1].split()[19])
            up = float(uptime.read().split()[0])
        return max(up - start_ticks / os.sysconf("SC_CLK_TCK"), 0.0)
    except (OSError, ValueError, IndexError):
        return 0.0


# Of a command's --time-limit, the part kept for the work after synthesis (writing the policy
# file, the summary): a share of the limit, at least AFTER_SYNTHESIS_MIN seconds.
AFTER_SYNTHESIS = 0.03
AFTER_SYNTHESIS_MIN = 0.1


def synthesis_time_left(time_limit: float) -> float:
    """The seconds a synthesis may take of a command's --time-limit, which bounds the whole
    command: the limit less the time since the command began (start-up, reading the inputs) and the
    reserve for writing the results; never below a tenth of the limit."""
    context = click.get_current_context(silent=True)
    start = context.find_object(CommandStart) if context is not None else None
    spent = time.perf_counter() - start.started if start is not None else 0.0
    reserve = max(AFTER_SYNTHESIS * time_limit, AFTER_SYNTHESIS_MIN)
    return max(time_limit - spent - reserve, 0.1 * time_limit)
