"""A settings object with some of its fields given by keyword: the API's calls and the gymnasium
environment take a frozen settings dataclass (`settings=`) and, for convenience, any of its
fields by name (`horizon=12`), so a signature stays short while each field keeps one default, the
settings object's."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

Settings = TypeVar("Settings", bound="DataclassInstance")


def with_options(settings: object, default: Settings, options: Mapping[str, Any], where: str) -> Settings:
    """`settings` (None: `default`) with the fields named in `options` replaced, checked again by
    its constructor. A `settings` that is not of `default`'s class, or a name that is not one of
    its fields, is a TypeError naming `where` and the class."""
    expected = type(default)
    if settings is None:
        settings = default
    elif not isinstance(settings, expected):
        raise TypeError(f"{where}() got settings of type {type(settings).__name__}; pass a "
                        f"{expected.__module__}.{expected.__qualname__}, or its fields by keyword "
                        f"({', '.join(f.name for f in dataclasses.fields(default))})")
    names = [field.name for field in dataclasses.fields(settings)]
    unknown = sorted(set(options) - set(names))
    if unknown:
        raise TypeError(f"{where}() got an unexpected keyword argument {unknown[0]!r}; it takes the fields "
                        f"of {type(settings).__name__}: {', '.join(names)}")
    return dataclasses.replace(settings, **options) if options else settings
