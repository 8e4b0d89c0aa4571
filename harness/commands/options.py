"""Range and finiteness checks of command-line options, done before any work starts.

click's FloatRange lets NaN through (every comparison with NaN is false), and an unbounded
integer such as `--horizon 10**18` would start work that can never finish: options go through
these types instead. A bad value is a one-line usage error with exit code 2. An option the API
takes too is `Checked` by the range both doors share (trustroute/core/ranges.py).
"""

from __future__ import annotations

import math
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


class FiniteFloat(click.ParamType):
    """A finite float within [minimum, maximum] (minimum excluded when `open_minimum`)."""

    name = "number"

    def __init__(self, minimum: float | None = None, maximum: float | None = None,
                 open_minimum: bool = False) -> None:
        self.minimum, self.maximum, self.open_minimum = minimum, maximum, open_minimum

    def convert(self, value, param, ctx):
        if isinstance(value, float):
            number = value
        else:
            try:
                number = float(value)
            except (TypeError, ValueError):
                self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        low = self.minimum
        if low is not None and (number <= low if self.open_minimum else number < low):
            self.fail(f"{number:g} must be {'>' if self.open_minimum else '>='} {low:g}", param, ctx)
        if self.maximum is not None and number > self.maximum:
            self.fail(f"{number:g} must be <= {self.maximum:g}", param, ctx)
        return number


def bounded_int(minimum: int, maximum: int) -> click.IntRange:
    return click.IntRange(minimum, maximum)


class Checked(click.ParamType):
    """An option that another door takes too: its value is parsed as the range's kind and checked
    by the range itself (trustroute/core/ranges.py `OptionRange`), the check the API makes, so
    both doors refuse it with the same words (an InputError: one line, exit code 2)."""

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
        """The kind and its range, as --help lists the option (`INTEGER 1..1000`, `NUMBER (0, 1]`)."""
        kind = self.accepted.kind
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
