"""Range and finiteness checks of command-line options, done before any work starts.

click's FloatRange lets NaN through (every comparison with NaN is false), and an unbounded
integer such as `--horizon 10**18` would start work that can never finish: options go through
these types instead. A bad value is a one-line usage error with exit code 2.
"""

from __future__ import annotations

import math

import click


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


SEED = bounded_int(0, 2**31 - 1)  # SUMO takes a signed 32-bit seed
HORIZON = bounded_int(1, 1_000)
JUNCTIONS = bounded_int(0, 10_000)
WORKERS = bounded_int(1, 256)
