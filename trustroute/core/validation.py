"""Input validation every loader uses: the guarded reader of input files, limited JSON and TOML
parsing, the strict key policy, required objects (docs/input_files.md); the field tables that
check each format's keys and values are trustroute/core/fields.py.

Every input file kind (town JSON, driver model JSON, spec TOML, study config TOML, policy JSON and
its .npz, a study's Parquet logs) is read through here, so every kind gets the same checks before
any parser sees a byte:

- the path is a regular file (not a FIFO, a device or a directory): opened non-blocking and
  checked with fstat, so a FIFO can never block the reader;
- its size is at most a cap (per kind; `MAX_TEXT_BYTES` for JSON/TOML);
- text is strict UTF-8 (the error names the line and column of the first bad byte), without a
  byte order mark;
- JSON is parsed with limits: nesting depth at most `MAX_DEPTH`, integers within the signed 64-bit
  range (`INT64_MIN`..`INT64_MAX`; literals of at most `MAX_INT_DIGITS` digits), finite floats
  only (no NaN/Infinity, no 1e400), and no duplicate keys in an object;
- TOML is pre-checked for nesting depth and integer size (tomllib itself recurses without a
  limit and converts integers of any length); nan is rejected (inf is left to the keys that
  allow it).

Every failure is an InputError (trustroute/core/errors.py) naming the file, the place and the fix, so a
bad input is one line on stderr and exit code 2 whatever kind of file it is. A row of a CSV file is
placed by the line an editor shows it on (`csv_place`), never by its index among the data rows.
"""

from __future__ import annotations

import csv
import difflib
import json
import math
import os
import re
import stat
import tomllib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from trustroute.core.errors import InputError

MAX_TEXT_BYTES = 16 * 1024 * 1024  # towns, driver models, specs, configs, policy documents
MAX_ARRAY_BYTES = 512 * 1024 * 1024  # policy .npz decision tables
MAX_DEPTH = 64  # nesting of JSON/TOML arrays and tables
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1  # every integer of an input fits an int64
MAX_INT_DIGITS = len(str(INT64_MAX))  # 19: a longer literal is out of range before it is parsed
MAX_TOML_KEY_PARTS = MAX_DEPTH  # dotted keys a.b.c... nest tables too
MAX_FILE_NAME = 64
# A name that becomes a file or folder name (a spec's names its policy cache entries, a study's its
# default folder): no path separators, NUL or leading dot, so it cannot point outside its folder.
FILE_NAME = re.compile(rf"[A-Za-z0-9_][A-Za-z0-9_.+-]{{0,{MAX_FILE_NAME - 1}}}")
FILE_NAME_RULE = f"1-{MAX_FILE_NAME} letters, digits, '_', '.', '+' or '-', not starting with '.'"
# A folder's path an input names: anything but a NUL byte, which no file system takes
PATH_TEXT = re.compile(r"[^\x00]+")

_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_TOML_STRINGS = re.compile(
    r'"""(?:[^\\]|\\.)*?"""|\'\'\'.*?\'\'\'|"(?:[^"\\\n]|\\.)*"|\'[^\'\n]*\'', re.DOTALL
)
_TOML_COMMENT = re.compile(r"#[^\n]*")
_TOML_INTEGER = re.compile(rf"(?<![\w.])[+-]?(?:0[xob])?[0-9a-fA-F_]{{{MAX_INT_DIGITS + 1},}}(?![\w.])")


def read_input_bytes(path: str | Path, what: str, max_bytes: int = MAX_TEXT_BYTES, fix: str = "",
                     shown: str | None = None) -> bytes:
    """The bytes of a regular file of at most `max_bytes`, or InputError (never blocks on a FIFO).
    `shown` names the file in errors (default: the path)."""
    shown = str(path) if shown is None else shown
    fix = fix or f"pass an existing {what}"
    if "\x00" in shown:
        raise InputError(repr(shown), "", f"the {what} path contains a NUL byte", fix)
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputError(shown, "", f"cannot read the {what} ({exc.strerror})", fix) from None
    try:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            kind = ("a directory" if stat.S_ISDIR(info.st_mode) else "a FIFO" if stat.S_ISFIFO(info.st_mode)
                    else "not a regular file")
            raise InputError(shown, "", f"the {what} is {kind}", fix)
        if info.st_size > max_bytes:
            raise InputError(shown, "", f"the {what} is {info.st_size} bytes, more than the "
                             f"{max_bytes}-byte limit", f"pass a real {what} (this one is far too large)")
        chunks = []
        remaining = max_bytes + 1  # a file that grows while we read is still capped
        while remaining > 0:
            chunk = os.read(descriptor, min(remaining, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            remaining -= len(chunk)
    except OSError as exc:
        raise InputError(shown, "", f"cannot read the {what} ({exc.strerror})", fix) from None
    finally:
        os.close(descriptor)
    data = b"".join(chunks)
    if len(data) > max_bytes:
        raise InputError(shown, "", f"the {what} is larger than the {max_bytes}-byte limit",
                         f"pass a real {what}")
    return data


def decode_utf8(data: bytes, source: str, what: str) -> str:
    """Strict UTF-8 text, or InputError naming the line and column of the first bad byte."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        before = data[: exc.start]
        line = before.count(b"\n") + 1
        column = exc.start - (before.rfind(b"\n") + 1) + 1
        raise InputError(source, f"line {line} column {column}", f"the {what} is not UTF-8 text "
                         f"(byte 0x{data[exc.start]:02x})", "save the file as UTF-8") from None


def read_input_text(path: str | Path, what: str, max_bytes: int = MAX_TEXT_BYTES, fix: str = "",
                    shown: str | None = None) -> str:
    shown = str(path) if shown is None else shown
    return decode_utf8(read_input_bytes(path, what, max_bytes, fix, shown), shown, what)


def read_text(path: str | Path, shown: str, what: str, fix: str) -> str:
    """The text of an input file through the guarded reader; `what` as in "the town file"."""
    noun = what[4:] if what.startswith("the ") else what
    return read_input_text(path, noun, fix=fix, shown=shown)


# -- JSON -----------------------------------------------------------------------------------------


def _line_column(text: str, offset: int) -> str:
    line = text.count("\n", 0, offset) + 1
    return f"line {line} column {offset - (text.rfind(chr(10), 0, offset) + 1) + 1}"


def _max_bracket_depth(text: str, openers: str, closers: str) -> tuple[int, int]:
    """(deepest nesting, offset where it is first reached) of brackets in text with strings removed."""
    codes = np.frombuffer(text.encode("utf-32-le"), dtype=np.uint32)
    step = np.zeros(codes.shape, dtype=np.int32)
    for char in openers:
        step[codes == ord(char)] = 1
    for char in closers:
        step[codes == ord(char)] = -1
    if not step.any():
        return 0, 0
    depth = np.cumsum(step)
    deepest = int(depth.max())
    return deepest, int(np.argmax(depth))


def _blank(match: re.Match) -> str:
    # Keep offsets (and newlines) so positions in the stripped text are positions in the file.
    return "".join("\n" if c == "\n" else " " for c in match.group())


def _refuse_bom(text: str, source: str, what: str) -> None:
    """InputError when text starts with a UTF-8 byte order mark (some Windows editors write one;
    neither JSON nor TOML allows it)."""
    if text.startswith("\ufeff"):
        raise InputError(source, "line 1 column 1", f"the {what} starts with a UTF-8 byte order mark "
                         "(BOM)", "save the file as UTF-8 without a BOM")


def parse_json(text: str, source: str, what: str = "file") -> object:
    """JSON with depth, number-size and duplicate-key limits, or InputError."""
    _refuse_bom(text, source, what)
    stripped = _JSON_STRING.sub(_blank, text)
    deepest, offset = _max_bracket_depth(stripped, "[{", "]}")
    if deepest > MAX_DEPTH:
        raise InputError(source, _line_column(text, offset), f"nested {deepest} levels deep (the limit "
                         f"is {MAX_DEPTH})", f"a {what} needs only a few levels; fix the file")

    refused: list[str] = []  # the hooks' refusals, located by key once the whole text is parsed

    def refuse(problem: str) -> _Refused:
        refused.append(problem)
        return _Refused(problem)

    def integer(literal: str) -> int | _Refused:
        if len(literal.lstrip("-")) > MAX_INT_DIGITS:
            return refuse(f"integer literal of {len(literal.lstrip('-'))} digits (the limit is "
                          f"{MAX_INT_DIGITS})")
        value = int(literal)
        if not INT64_MIN <= value <= INT64_MAX:
            return refuse(f"integer {literal} is out of the 64-bit range")
        return value

    def real(literal: str) -> float | _Refused:
        value = float(literal)
        if not math.isfinite(value):
            return refuse(f"number {literal[:24]} is out of the floating-point range")
        return value

    def constant(name: str) -> _Refused:
        return refuse(f"{name} is not a number JSON allows")

    def no_duplicates(pairs: list[tuple[str, object]]) -> dict:
        out: dict = {}
        for key, value in pairs:
            if key in out:
                refused.append(key)
                return _RepeatedKey(pairs, key)
            out[key] = value
        return out

    try:
        data = json.loads(text, parse_int=integer, parse_float=real, parse_constant=constant,
                          object_pairs_hook=no_duplicates)
    except json.JSONDecodeError as exc:
        raise InputError(source, f"line {exc.lineno} column {exc.colno}", f"not valid JSON ({exc.msg})",
                         "fix the JSON syntax") from None
    except (RecursionError, ValueError, MemoryError) as exc:
        raise InputError(source, "", f"cannot parse the {what} ({type(exc).__name__})",
                         "fix the JSON") from None
    if refused:
        place, problem = _first_refusal(data)
        raise InputError(source, place, problem, f"fix the {what}: numbers must be ordinary finite "
                         "values and every key appears once")
    return data


class _Refused:
    """A value the JSON/TOML number hooks refuse, left in place so the error can name its key."""

    __slots__ = ("problem",)

    def __init__(self, problem: str) -> None:
        self.problem = problem


class _RepeatedKey(dict):
    """A JSON object that gives `key` twice, left in place so the error can name where."""

    def __init__(self, pairs: list[tuple[str, object]], key: str) -> None:
        super().__init__(pairs)
        self.key = key


def _first_refusal(data: object) -> tuple[str, str]:
    """(key path such as `types[0].weight`, problem) of the first refused value or repeated key of
    parsed data, in the order of the file."""
    stack: list[tuple[str, object]] = [("", data)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, _Refused):
            return path or "top level", value.problem
        if isinstance(value, _RepeatedKey):
            return key_place(path, value.key), f"duplicate key {value.key[:40]!r} in one object"
        if isinstance(value, dict):
            stack.extend(reversed([(key_place(path, str(key)), item) for key, item in value.items()]))
        elif isinstance(value, list):
            stack.extend(reversed([(f"{path}[{index}]", item) for index, item in enumerate(value)]))
    return "", "a value is refused"


def read_json(path: str | Path, what: str, max_bytes: int = MAX_TEXT_BYTES, fix: str = "") -> object:
    """Read and parse a JSON input file with every guard; `what` names it in errors."""
    shown = str(path)
    return parse_json(read_input_text(path, what, max_bytes, fix), shown, what)


# -- TOML -----------------------------------------------------------------------------------------


def parse_toml(text: str, source: str, what: str = "file") -> dict:
    """TOML with depth, integer-size and finiteness limits, or InputError."""
    _refuse_bom(text, source, what)
    stripped = _TOML_STRINGS.sub(_blank, text)
    stripped = _TOML_COMMENT.sub(_blank, stripped)
    deepest, offset = _max_bracket_depth(stripped, "[{", "]}")
    if deepest > MAX_DEPTH:
        raise InputError(source, _line_column(text, offset), f"nested {deepest} levels deep (the limit "
                         f"is {MAX_DEPTH})", f"a {what} needs only a few levels; fix the file")
    for big in _TOML_INTEGER.finditer(stripped):
        if sum(c.isdigit() for c in big.group()) <= MAX_INT_DIGITS:
            continue
        raise InputError(source, _line_column(text, big.start()), f"integer literal of "
                             f"{sum(c.isdigit() for c in big.group())} digits (the limit is "
                             f"{MAX_INT_DIGITS})", f"fix the {what}: write an ordinary number")

    refused = False

    def real(literal: str) -> float | _Refused:
        # TOML's inf stays allowed (e.g. a population's concentration = inf); keys that need a
        # finite value check it. nan is never a meaningful setting.
        nonlocal refused
        value = float(literal)
        if math.isnan(value):
            refused = True
            return _Refused(f"{literal[:24]} is not a number")
        return value

    try:
        data = tomllib.loads(text, parse_float=real)
    except tomllib.TOMLDecodeError as exc:
        where = re.search(r"\(at line (\d+), column (\d+)\)", str(exc))
        place = f"line {where.group(1)} column {where.group(2)}" if where else ""
        message = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(exc))
        raise InputError(source, place, f"not valid TOML ({message})", "fix the TOML syntax") from None
    except (RecursionError, ValueError, MemoryError) as exc:
        raise InputError(source, "", f"cannot parse the {what} ({type(exc).__name__})",
                         "fix the TOML") from None
    _check_depth(data, source, what)
    if refused:
        place, problem = _first_refusal(data)
        raise InputError(source, place, problem, f"fix the {what}: numbers must be finite")
    return data


def _check_depth(data: object, source: str, what: str) -> None:
    """Iterative depth and integer-range check of parsed data (dotted keys nest without brackets)."""
    stack: list[tuple[object, int]] = [(data, 0)]
    while stack:
        value, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise InputError(source, "", f"nested more than {MAX_DEPTH} levels deep",
                             f"a {what} needs only a few levels; fix the file")
        if isinstance(value, dict):
            stack.extend((v, depth + 1) for v in value.values())
        elif isinstance(value, list):
            stack.extend((v, depth + 1) for v in value)
        elif isinstance(value, int) and not isinstance(value, bool) and not INT64_MIN <= value <= INT64_MAX:
            raise InputError(source, "", f"integer {str(value)[:40]} is out of the 64-bit range",
                             f"fix the {what}: write an ordinary number")


def read_toml(path: str | Path, what: str, max_bytes: int = MAX_TEXT_BYTES, fix: str = "") -> dict:
    """Read and parse a TOML input file with every guard; `what` names it in errors."""
    return parse_toml(read_input_text(path, what, max_bytes, fix), str(path), what)


# -- CSV --------------------------------------------------------------------------------------------


def csv_line(path: str | Path, row: int) -> int:
    """The line of `path`, numbered from 1 as an editor shows it, where data row `row` starts; rows
    count from 0 after the header, as pandas reads them (blank lines skipped, a quoted cell may
    span lines). Read only when an error names a row, so a valid file is read once."""
    with open(path, newline="", encoding="utf-8", errors="replace") as handle:
        reader = csv.reader(handle)
        start, index = 1, -1   # the header is the record before row 0
        for record in reader:
            # pandas skips a line of nothing or of white space alone; a line `""` (one empty quoted
            # cell, the record [""]) is a row of empty cells to it
            if record and (len(record) > 1 or record[0] == "" or record[0].strip()):
                if index == row:
                    return start
                index += 1
            start = reader.line_num + 1
    return start


def csv_place(path: str | Path, row: int, column: str = "") -> str:
    """The place of data row `row` (and `column`) of a CSV file in an error: "line 42, column x"."""
    line = f"line {csv_line(path, row)}"
    return f"{line}, column {column}" if column else line


# -- documented key policy --------------------------------------------------------------------------


Place = str | Callable[[str], str]


def key_place(place: Place, key: str) -> str:
    """Where `key` of a table is: `place` is the table's own dotted place ("" at the top of a file)
    or a function of the key (a spec places keys by line and column)."""
    if callable(place):
        return place(key)
    return f"{place}.{key}" if place else key


# The longest list of keys an unknown-key fix spells out; a longer one (a study config's, a policy
# file's) would not fit the capped line, so the fix names the closest key and the doc listing them.
LISTED_KEYS_MAX = 150
KEYS_DOC = 'docs/input_files.md'


def check_keys(data: dict, allowed: tuple[str, ...], source: str, place: Place, what: str) -> None:
    """Strict key policy (docs/input_files.md): a key the format does not define is an error."""
    unknown = sorted(str(k) for k in data if k not in allowed)
    if unknown:
        where = key_place(place, unknown[0])
        raise InputError(source, where, f"unknown key {unknown[0][:60]!r} in the {what}",
                         unknown_key_fix(unknown[0], allowed, what))


def unknown_key_fix(key: str, allowed: tuple[str, ...], what: str) -> str:
    """The fix of an unknown key: the closest allowed key when one is close, and the allowed keys,
    spelt out when they fit the line, else where docs/input_files.md lists them."""
    listed = ", ".join(allowed)
    short = len(listed) <= LISTED_KEYS_MAX
    closest = difflib.get_close_matches(key, allowed, n=1)
    if closest:
        others = f"one of {listed}" if short else f"another key of the {what} {KEYS_DOC} lists"
        fix = f"write {closest[0]}, the closest key, or {others}"
    else:
        fix = f"use only {listed}" if short else f"use only the keys of the {what} {KEYS_DOC} lists"
    return f"{fix} (a misspelt key would be ignored otherwise)"


# -- beliefs ----------------------------------------------------------------------------------------

BELIEF_TOLERANCE = 1e-6  # a stored belief's entries sum to 1 within this (rounding of logs and tables)


def first_non_belief(rows: np.ndarray) -> tuple[int, str] | None:
    """(first row, what is wrong) of the rows of `rows` [n, k] that are not probability vectors
    (finite entries in [0, 1] summing to 1 within BELIEF_TOLERANCE); None when every row is one.
    The one rule for beliefs read from a file: the dataset's tables, the CARLA logs, policy tables."""
    rows = np.asarray(rows, dtype=float)
    finite = np.isfinite(rows).all(axis=1)
    in_range = finite & ((rows >= 0) & (rows <= 1)).all(axis=1)
    sums = np.where(np.isfinite(rows), rows, 0.0).sum(axis=1)
    bad = np.flatnonzero(~(in_range & (np.abs(sums - 1) <= BELIEF_TOLERANCE)))
    if not bad.size:
        return None
    row = int(bad[0])
    if not finite[row]:
        return row, "an entry is not a finite number"
    if not in_range[row]:
        return row, "an entry lies outside [0, 1]"
    return row, f"the entries sum to {sums[row]:.9g}, not 1 (tolerance {BELIEF_TOLERANCE:g})"


def require_object(data: object, shown: str, fix: str) -> dict:
    """`data` itself when it is a JSON object (a dict); InputError at "top level" otherwise."""
    if not isinstance(data, dict):
        raise InputError(shown, "top level", "expected a JSON object", fix)
    return data
