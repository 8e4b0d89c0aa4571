"""Field tables: the declarative schema of every input format, and the one validator that walks a
parsed document against one.

A field table is a tuple of `Field`s, one per accepted key: its kind (`Integer`, `Number`, `Text`,
`Flag`, `OneOf`, `ListOf`, `Table`, `Anything`; `PROBABILITY` for a number in [0, 1]), whether it
is required or else its default, the range the kind allows, and the fix a bad value's message
names. `check_fields` checks a parsed table against it: unknown keys first (the strict key policy,
`check_keys`), then the missing required keys in table order, then every present value in table
order; it returns every key's value with the defaults filled in. `check_value` checks one value
against a kind (the loaders' per-entry checks use it). Every failure is the one-line
`InputError(file, place, problem, fix)`.

Types: a kind of `T` (`Kind[T]`: `Integer` is a `Kind[int]`, `ListOf(item=Text())` a
`Kind[list[str]]`) makes `check_value` return a `T`. A format's table is made by
`field_table(Values, *fields)`, `Values` a TypedDict with one key per field typed as its kind
accepts; `check_fields` returns that TypedDict, so a loader reads typed values.

Messages: a kind states its own problem ("expected an integer from 1 to 1000, got 0"); a field (or
a kind instance used as the values of a table) may give its own `problem` and `fix`, either text
or a function of what was seen (`Seen`: key, value and the owning entry, e.g. an atom's name).

A rule a table cannot express (a road names two junctions of the same file, rows sum to 1, a path
resolves to a file) stays a small named check beside its loader's table. `keys(FIELDS)` is the
set of accepted keys of a format, what its docs table (docs/formats/) lists.

bool is an int subclass in Python: no number kind accepts `true` or `false`.
"""

from __future__ import annotations

import math
import numbers
import os
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Generic, NamedTuple, TypeGuard, TypeVar, cast, overload

from trustroute.core.errors import InputError
from trustroute.core.validation import Place, check_keys, key_place
from trustroute.core.wording import shown_value


@dataclass(frozen=True)
class Seen:
    """What a message is about: the key, the value found there, and the entry owning the table
    (an atom's name; "" at the top of a file)."""

    key: str
    value: object
    owner: str = ""


Message = str | Callable[[Seen], str]
T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)
D = TypeVar("D")  # a format's checked values: a TypedDict with one key per field
EMPTY: Mapping[str, object] = MappingProxyType({})  # the default of an optional table (never mutated)


class Rejection(NamedTuple):
    """A kind's own account of a bad value: `fix` when the failure has a fix of its own (it comes
    before the field's), `hint` a fix to fall back on when the field gives none."""

    problem: str
    fix: str | None = None
    hint: str = ""


@overload
def say(message: Message, seen: Seen) -> str: ...
@overload
def say(message: Message | None, seen: Seen) -> str | None: ...
def say(message: Message | None, seen: Seen) -> str | None:
    """The text of a message (a function of what was seen, or fixed text)."""
    return message(seen) if callable(message) else message


def is_number(value: object) -> TypeGuard[int | float]:
    """A finite int or float, not a bool."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    return isinstance(value, int) or math.isfinite(value)


def holds_bool(value: object) -> bool:
    """True if `value` is a bool or a (nested) list holding one: a number array must not."""
    if isinstance(value, bool):
        return True
    return isinstance(value, list) and any(holds_bool(item) for item in value)


# -- kinds ------------------------------------------------------------------------------------------
# Every kind may carry its own `problem`/`fix` (used where the kind checks the entries of a table).


@dataclass(frozen=True, kw_only=True)
class Kind(Generic[T_co]):
    """What a value must be, a `T_co` when good; `reject` gives None for a good value, else the kind's
    account of it."""

    problem: Message | None = None
    fix: Message | None = None
    plural = "values"  # the kind's values, in a list's message ("a list of integers")

    def reject(self, value: object) -> Rejection | None:
        return None


@dataclass(frozen=True, kw_only=True)
class Anything(Kind[object]):
    """Any value (checked by a rule of the loader, or kept as it is)."""


@dataclass(frozen=True, kw_only=True)
class Integer(Kind[int]):
    """An int (not a bool) in [minimum, maximum]; `false_allowed`: `false` too (a rule it turns off)."""

    minimum: int = -(2**63)
    maximum: int = 2**63 - 1
    false_allowed: bool = False
    plural = "integers"

    def reject(self, value: object) -> Rejection | None:
        if self.false_allowed and value is False:
            return None
        if isinstance(value, bool) or not isinstance(value, int) or not self.minimum <= value <= self.maximum:
            return Rejection(f"expected an integer from {self.minimum} to {self.maximum}, "
                             f"got {shown_value(value)}")
        return None


@dataclass(frozen=True, kw_only=True)
class Number(Kind[float]):
    """An int or float (not a bool), finite unless `finite` is False, within the bounds (`open_below`
    / `open_above`: the bound itself excluded)."""

    minimum: float = -math.inf
    maximum: float = math.inf
    open_below: bool = False
    open_above: bool = False
    finite: bool = True
    plural = "numbers"

    def reject(self, value: object) -> Rejection | None:
        if self.finite and isinstance(value, float) and not math.isfinite(value):
            return Rejection(f"{shown_value(value)} is not a finite number")
        if not self._accepts(value):
            return Rejection(f"{shown_value(value)} is not a number in {self.interval()}")
        return None

    def _accepts(self, value: object) -> bool:
        if not (is_number(value) or (not self.finite and isinstance(value, float) and not math.isnan(value))):
            return False
        below = value > self.minimum if self.open_below else value >= self.minimum
        above = value < self.maximum if self.open_above else value <= self.maximum
        return below and above

    def interval(self) -> str:
        """The values taken, as an interval: an infinite end is open where the number is finite."""
        below = self.open_below or (self.finite and self.minimum == -math.inf)
        above = self.open_above or (self.finite and self.maximum == math.inf)
        return f"{'(' if below else '['}{self.minimum:g}, {self.maximum:g}{')' if above else ']'}"


PROBABILITY = Number(minimum=0.0, maximum=1.0,
                     problem=lambda seen: f"{shown_value(seen.value)} is not a probability in [0, 1]",
                     fix="give a number in [0, 1]")


@dataclass(frozen=True, kw_only=True)
class Text(Kind[str]):
    """A string: non-empty unless `nonempty` is False, at most `max_length` characters, matching
    `pattern` in full when given."""

    nonempty: bool = True
    max_length: int | None = None
    pattern: re.Pattern[str] | None = None
    plural = "strings"

    def reject(self, value: object) -> Rejection | None:
        ok = (isinstance(value, str) and (value or not self.nonempty)
              and (self.max_length is None or len(value) <= self.max_length)
              and (self.pattern is None or self.pattern.fullmatch(value) is not None))
        if not ok:
            size = "non-empty " if self.nonempty else ""
            return Rejection(f"expected a {size}string, got {shown_value(value)}")
        return None


@dataclass(frozen=True, kw_only=True)
class Flag(Kind[bool]):
    """`true` or `false`."""

    plural = "booleans"

    def reject(self, value: object) -> Rejection | None:
        if isinstance(value, bool):
            return None
        return Rejection(f"expected true or false, got {shown_value(value)}")


@dataclass(frozen=True, kw_only=True)
class OneOf(Kind[T_co]):
    """One of `choices` (of the same type: `true` is not 1); `noun` names a value in messages."""

    choices: tuple[T_co, ...] = ()
    noun: str = "value"

    def reject(self, value: object) -> Rejection | None:
        if any(type(value) is type(choice) and value == choice for choice in self.choices):
            return None
        return Rejection(f"unknown {self.noun} {shown_value(value)}",
                         hint=f"use one of {', '.join(map(str, self.choices))}")


# A list's items when no kind is given: any value (the loader checks them one by one). Typed as a
# kind of every item type, so that a list left unchecked item by item fits any list a loader reads.
UNCHECKED_ITEMS: Kind[Any] = Anything()


@dataclass(frozen=True, kw_only=True)
class ListOf(Kind[list[T]]):
    """A list of `min_items` to `max_items` items of kind `item`, checked as one value (its message
    names the whole list); `distinct`: no item twice; `increasing`: each item above the last."""

    item: Kind[T] = UNCHECKED_ITEMS
    min_items: int = 0
    max_items: int | None = None
    distinct: bool = False
    increasing: bool = False
    plural = "lists"

    def reject(self, value: object) -> Rejection | None:
        if not (isinstance(value, list) and self._shaped(value)):
            size = "non-empty " if self.min_items == 1 and self.max_items is None else ""
            order = "increasing " if self.increasing else ""
            return Rejection(f"expected a {size}{order}list of {self.item.plural}, "
                             f"got {shown_value(value, 60)}")
        if self.distinct and _repeats(value):
            return Rejection("lists the same entry twice", "list each entry once")
        return None

    def _shaped(self, items: list) -> bool:
        """The length in bounds, every item of kind `item` and, when `increasing`, in order."""
        return (self.min_items <= len(items) and (self.max_items is None or len(items) <= self.max_items)
                and not any(self.item.reject(entry) for entry in items)
                and not (self.increasing and any(a >= b for a, b in zip(items, items[1:], strict=False))))


def _repeats(items: list) -> bool:
    try:
        return len(set(items)) != len(items)
    except TypeError:  # unhashable items
        return any(a == b for i, a in enumerate(items) for b in items[i + 1:])


@dataclass(frozen=True, kw_only=True)
class Table(Kind[dict[str, object]]):
    """An object (JSON) or table (TOML); non-empty when `nonempty`. With `values`, every entry's
    value is checked against that kind at `place.key`."""

    nonempty: bool = False
    values: Kind[object] | None = None
    plural = "tables"

    def reject(self, value: object) -> Rejection | None:
        if not isinstance(value, dict) or (self.nonempty and not value):
            return Rejection(f"expected a {'non-empty ' if self.nonempty else ''}table")
        return None


def is_whole(value: object) -> TypeGuard[numbers.Integral]:
    """A whole number as the CLI parses one: an int or a numpy integer, not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def is_real(value: object) -> TypeGuard[numbers.Real]:
    """A real number: an int, a float, a numpy number, not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def as_python(value: object, kind: Kind[Any]) -> object:
    """`value` as Python's own where numpy's or a script's stands in for it: a numpy array as a
    list, a numpy scalar (a bool, a string, a number) as the Python one, a tuple as a list where a
    list is expected, a path (pathlib's) as its string where a string is; then a whole number as an
    int where an integer or a number is expected, any other real number as a float where a number
    is, in a list's items and a table's entries too; a bool and every other value as it is, for the
    kind to judge. A document or a keyword a script computed is then checked, kept and written
    (TOML, JSON) as the one a file or the CLI gives."""
    numpy = sys.modules.get("numpy")   # a numpy value means numpy is imported: never imported here
    if numpy is not None and isinstance(value, numpy.ndarray | numpy.generic):
        value = value.tolist()
    if isinstance(kind, ListOf) and isinstance(value, tuple):
        value = list(value)
    if isinstance(kind, Text) and isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(kind, Integer | Number) and is_whole(value):
        return int(value)
    if isinstance(kind, Number) and is_real(value):
        return float(value)
    if isinstance(kind, ListOf) and isinstance(value, list):
        return [as_python(item, kind.item) for item in value]
    if isinstance(kind, Table) and kind.values is not None and isinstance(value, dict):
        return {key: as_python(entry, kind.values) for key, entry in value.items()}
    return value


# -- fields and the validator -------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Field:
    """One accepted key of a table: its kind, required or its default, and its messages (`problem`
    replaces the kind's account of a bad value; `missing`/`missing_fix` when a required key is
    absent: default "missing key 'k'" and `fix`)."""

    key: str
    kind: Kind[object]
    required: bool = False
    default: object = None
    fix: Message = ""
    problem: Message | None = None
    missing: Message | None = None
    missing_fix: Message | None = None


def keys(fields: Sequence[Field]) -> tuple[str, ...]:
    """The keys a field table accepts, in table order."""
    return tuple(field.key for field in fields)


class FieldTable(tuple[Field, ...], Generic[D]):
    """A field table whose checked values are a `D`: a TypedDict with one key per field, typed as
    the field's kind accepts (`| None` for an optional key without a default). Made by `field_table`."""


def field_table(values: type[D], *fields: Field) -> FieldTable[D]:
    """The table of `fields`, whose checked values `values` (a TypedDict) describes; TypeError when
    the TypedDict's keys are not the fields' keys."""
    if sorted(values.__annotations__) != sorted(keys(fields)):
        raise TypeError(f"{values.__name__} has keys {sorted(values.__annotations__)}, "
                        f"the fields {sorted(keys(fields))}")
    return FieldTable(fields)


def check_value(value: object, kind: Kind[T], source: str, place: str, problem: Message | None = None,
                fix: Message | None = None, seen: Seen | None = None) -> T:
    """`value` when `kind` accepts it, its numbers as Python's (`as_python`; a table's entries
    checked too); InputError otherwise. `problem`/`fix` replace the kind's messages (as a field's do)."""
    value = as_python(value, kind)
    rejection = kind.reject(value)
    if rejection is not None:
        seen = seen if seen is not None else Seen("", value)
        given = problem if problem is not None else kind.problem
        fix_text = say(fix or kind.fix, seen) or ""
        if given is not None:
            raise InputError(source, place, say(given, seen), fix_text)
        raise InputError(source, place, rejection.problem, rejection.fix or fix_text or rejection.hint)
    if isinstance(kind, Table) and kind.values is not None and isinstance(value, dict):
        for key, entry in value.items():
            check_value(entry, kind.values, source, f"{place}.{key}",
                        seen=Seen(str(key), entry, seen.owner if seen else ""))
    return cast(T, value)  # the kind accepted it: a T


def check_fields(data: dict, fields: FieldTable[D], source: str, what: str, place: Place = "",
                 owner: str = "") -> D:
    """Check the parsed table `data` against `fields`: no unknown key (`what` names the table in
    that message), every required key present, every value of its kind. Returns every field's
    value by key (the table's TypedDict), the default where the key is absent. `owner` names the
    entry the table belongs to in messages (`Seen.owner`)."""
    check_keys(data, keys(fields), source, place, what)
    for field in fields:
        if field.required and field.key not in data:
            seen = Seen(field.key, None, owner)
            raise InputError(source, key_place(place, field.key),
                             say(field.missing, seen) or f"missing key '{field.key}'",
                             say(field.missing_fix or field.fix, seen) or "")
    values: dict[str, object] = {}
    for field in fields:
        if field.key not in data:
            values[field.key] = field.default
            continue
        value = data[field.key]
        values[field.key] = check_value(value, field.kind, source, key_place(place, field.key), field.problem,
                                        field.fix, Seen(field.key, value, owner))
    return cast(D, values)  # every field's key, each value of its kind or the field's default: a D
