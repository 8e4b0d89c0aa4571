"""A command's options as frozen dataclasses, each option declared once.

A field made with `option(...)` is a command-line option: its flags, type, default and help are
the arguments of that one call (click.option's), its Python name is the field's name. `takes`
adds the fields' options to a click command in field order (so --help lists them as declared) and
hands the command one object per group, built once from the values click parsed, instead of one
parameter per option: `synth(spec_path, options)`. A group turns its values into the settings
object the application layer takes (SynthesisSettings, EvaluationSettings, ServerOptions, ...) in
one method, so a command neither repeats a default nor rebuilds its settings.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import Field, field, fields
from typing import Any

import click

_OPTION = "click_option"   # a field's metadata key: (flags, click.option's keyword arguments)


def option(*flags: str, **attrs: Any) -> Any:
    """A dataclass field that is the option `click.option(*flags, <field name>, **attrs)`; the
    field's default is the value click gives when the option is not passed."""
    if attrs.get("multiple"):
        default: object = tuple(attrs.get("default") or ())
    elif "default" in attrs:
        default = attrs["default"]
    else:
        default = False if attrs.get("is_flag") else None
    return field(default=default, metadata={_OPTION: (flags, attrs)})


def option_decorator(name: str, made: Field) -> Callable:
    """The click decorator of a field made by `option` (for a command that takes it alone)."""
    flags, attrs = made.metadata[_OPTION]
    return click.option(*flags, name, **attrs)


def takes(**groups: type) -> Callable[[Callable], Callable]:
    """Add the options of each group (a dataclass of `option` fields) to the command, in order,
    and pass the command `name=Group(**its values)` for each `name=Group`."""

    def decorate(function: Callable) -> Callable:
        @functools.wraps(function)
        def callback(*args: Any, **values: Any) -> Any:
            built = {name: group(**{f.name: values.pop(f.name) for f in fields(group)})
                     for name, group in groups.items()}
            return function(*args, **values, **built)

        decorated: Callable = callback
        for group in reversed(groups.values()):
            for made in reversed(fields(group)):
                decorated = option_decorator(made.name, made)(decorated)
        return decorated

    return decorate
