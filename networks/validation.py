"""The small set of input-validation helpers every loader uses (town, driver model, spec, study
config, policy file): read a file, parse JSON or TOML, require an object and its keys.

Each raises `InputError` (networks/errors.py) naming the file, the place and the fix, so a bad
input is one line on stderr and exit code 2 whatever kind of file it is.
"""

from __future__ import annotations

import json
import re
import tomllib
from collections.abc import Callable, Iterable
from pathlib import Path

from trustroute.networks.errors import InputError

_TOML_POSITION = re.compile(r"\s*\(at line (\d+), column (\d+)\)")


def read_text(path: str | Path, shown: str, what: str, fix: str) -> str:
    """The text of `path`; InputError "cannot read <what> (reason)" when it cannot be read."""
    try:
        return Path(path).read_text()
    except OSError as exc:
        raise InputError(shown, "", f"cannot read {what} ({exc.strerror})", fix) from None


def parse_json(text: str, shown: str) -> object:
    """Parsed JSON; InputError at "line L column C" when the syntax is wrong."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(shown, f"line {exc.lineno} column {exc.colno}", f"not valid JSON ({exc.msg})",
                         "fix the JSON syntax") from None


def parse_toml(text: str, shown: str) -> dict:
    """Parsed TOML; InputError at "line L column C" (when tomllib gives it) when the syntax is wrong."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        where = _TOML_POSITION.search(str(exc))
        place = f"line {where.group(1)} column {where.group(2)}" if where else ""
        message = _TOML_POSITION.sub("", str(exc))
        raise InputError(shown, place, f"not valid TOML ({message})", "fix the TOML syntax") from None


def require_object(data: object, shown: str, fix: str) -> dict:
    """`data` itself when it is a JSON object (a dict); InputError at "top level" otherwise."""
    if not isinstance(data, dict):
        raise InputError(shown, "top level", "expected a JSON object", fix)
    return data


def require_keys(data: dict, keys: Iterable[str], shown: str, fix: Callable[[str], str]) -> None:
    """InputError "missing key 'k'" at the first of `keys` absent from `data`; fix(k) says how."""
    for key in keys:
        if key not in data:
            raise InputError(shown, key, f"missing key '{key}'", fix(key))
