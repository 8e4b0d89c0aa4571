"""What every command prints: the --json and --quiet options, and one JSON convention.

A command that prints results takes `--json`: it then prints exactly one JSON object on stdout and
nothing else. The files a command wrote are listed under one key, `"paths"`, as name -> path
(e.g. {"policy": ..., "rrd": ...}), the same key in every command, present (empty) when the
command wrote nothing. A command with progress output
takes `--quiet` (no progress bars, no chatter; `--json` implies it).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import click
import numpy as np

from trustroute.harness.commands.option_groups import option, option_decorator

PATHS_KEY = "paths"


def json_flag() -> Any:
    """--json, as a field of a command's options (harness/commands/option_groups.py)."""
    return option("--json", is_flag=True, help="Print one JSON object (written files under \"paths\").")


def quiet_flag() -> Any:
    """--quiet, as a field of a command's options."""
    return option("--quiet", "-q", is_flag=True, help="No progress bars or chatter.")


json_option = option_decorator("as_json", json_flag())
quiet_option = option_decorator("quiet", quiet_flag())


def jsonable(value: object) -> object:
    """numpy scalars and arrays, paths and sets as plain JSON values."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, set | frozenset | tuple):
        return list(value)
    return str(value)


def with_paths(payload: Mapping, paths: Mapping[str, object]) -> dict:
    """`payload` plus the written files under "paths" (None entries left out)."""
    return {**payload, PATHS_KEY: {name: str(path) for name, path in paths.items() if path is not None}}


def emit(as_json: bool, payload: Mapping, lines: list[str]) -> None:
    """One JSON object (--json; with "paths", empty when nothing was written) or the lines."""
    if as_json:
        if PATHS_KEY not in payload:
            payload = with_paths(payload, {})
        click.echo(json.dumps(payload, default=jsonable))
    else:
        for line in lines:
            click.echo(line)


def warn(line: str) -> None:
    """A warning: one line on stderr, `warning: ` before it, with or without --json (whose object
    lists the command's warnings under "warnings")."""
    click.echo(f"warning: {line}", err=True)


def study_warnings(study_dir: Path) -> list[str]:
    """What a command reading the study directory cannot check, said (`warn`) before it reads the
    study, so a command that then fails has said it too; the lines, for --json's "warnings": a
    manifest without the hash of its config (harness/study/inputs.py, `unchecked_config`, which
    the replay says too)."""
    from trustroute.core.dataset import read_manifest
    from trustroute.core.package import is_package
    from trustroute.harness.study.inputs import unchecked_config

    # a package's manifest always records its config's hash (harness/study/export.py)
    line = None if is_package(study_dir) else unchecked_config(read_manifest(study_dir), study_dir)
    warnings = [] if line is None else [line]
    for warning in warnings:
        warn(warning)
    return warnings
