"""The arguments and options that name an input, each with one help text wherever it appears:
SPEC, --town and --driver take a file or a packaged name (trustroute/core/packaged.py;
docs/input_files.md, "Packaged names")."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import click

from trustroute.harness.commands.option_groups import option, option_decorator

SPEC_HELP = "SPEC is a spec file or a packaged spec name, e.g. phi1."
TOWN_HELP = "Town file or packaged town name, e.g. city"
DRIVER_HELP = "Driver model file or packaged name (default: the packaged model)."
# what --population takes, at the head of each command's help for it
POPULATION_GIVEN = "Driver-population file or packaged name (e.g. driver_population_three_types)"


def spec_argument(name: str = "spec_path", **attrs: Any) -> Callable[[Callable], Callable]:
    """The SPEC argument (the function's parameter `name`), and SPEC_HELP added to the command's
    help: put it under @click.command, which reads the help from the docstring."""

    def decorate(function: Callable) -> Callable:
        function.__doc__ = f"{inspect.cleandoc(function.__doc__ or '')}\n\n{SPEC_HELP}"
        return click.argument(name, metavar="SPEC", **attrs)(function)

    return decorate


def town_field(with_spec: bool = True) -> Any:
    """--town, as a field of a command's options; `with_spec`: the command takes a SPEC, and a
    packaged spec brings the town it is written for."""
    default = ("the town a packaged spec is written for, else the packaged town" if with_spec
               else "the packaged town")
    return option("--town", type=click.Path(), default=None, help=f"{TOWN_HELP} (default: {default}).")


def driver_field() -> Any:
    """--driver, as a field of a command's options."""
    return option("--driver", type=click.Path(), default=None, help=DRIVER_HELP)


town_option = option_decorator("town_path", town_field())
town_only_option = option_decorator("town_path", town_field(with_spec=False))   # commands without SPEC
driver_option = option_decorator("driver_path", driver_field())
