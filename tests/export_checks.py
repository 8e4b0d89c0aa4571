"""Checks of an exported package (`trustroute export`) shared by the simulated and the live export
tests: its rows in pseudonym order, each participant's in the study's own order, no wall-clock
time in any table, the inputs that define the task where its config names them, and nothing of the
lab's disk or of a participant's identity in any file."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from trustroute.harness.study.export import read_export_keys

ISO_DATE_TIME = re.compile(r"\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}")
EPISODE_CODE = re.compile(r"^p(\d{5})-")


def row_codes(table: pa.Table) -> list[int]:
    """Each row's participant (number or code): its `participant`, else its `episode_id`'s."""
    if "participant" in table.schema.names:
        return table.column("participant").to_pylist()
    return [int(EPISODE_CODE.match(e).group(1)) for e in table.column("episode_id").to_pylist()]


def package_key(study_dir: Path, package: Path) -> dict[int, int]:
    """The key (participant number -> code) of `package`, as the study's key file holds it: the
    newest entry of its path, the package the path holds now."""
    entry = [entry for entry in read_export_keys(study_dir) if entry["package"] == str(package.resolve())][-1]
    return {int(p): code for p, code in entry["pseudonyms"].items()}


def assert_rows_in_code_order(package: Path, study_dir: Path) -> None:
    """Every table of the package has its rows sorted by pseudonym, and a participant's rows are the
    study table's rows of that participant in the study's order (compared on their episode ids)."""
    key = package_key(study_dir, package)
    code_of = {f"p{p:05d}-": f"p{code:05d}-" for p, code in key.items()}
    for path in sorted((package / "tables").glob("*.parquet")):
        exported, study = pq.read_table(path), pq.read_table(study_dir / path.name)
        codes = row_codes(exported)
        assert codes == sorted(codes), path.name
        if "episode_id" not in exported.schema.names:
            continue
        for p, code in key.items():
            mine = [e for e, c in zip(study.column("episode_id").to_pylist(), row_codes(study), strict=True)
                    if c == p]
            theirs = [e for e, c in zip(exported.column("episode_id").to_pylist(), codes, strict=True)
                      if c == code]
            assert theirs == [None if e is None else code_of[e[:7]] + e[7:] for e in mine], path.name


def assert_no_wall_clock(package: Path) -> None:
    """No column of any table is a date or time type, none is in UTC by the codebook, and no text value
    holds a date and time of day."""
    book = json.loads((package / "codebook.json").read_text())
    assert not [entry["column"] for entries in book.values() for entry in entries if entry["unit"] == "UTC"]
    for path in sorted((package / "tables").glob("*.parquet")):
        table = pq.read_table(path)
        for field in table.schema:
            assert not (pa.types.is_temporal(field.type)), (path.name, field.name)
            if pa.types.is_string(field.type):
                dated = [v for v in table.column(field.name).to_pylist() if v and ISO_DATE_TIME.search(v)]
                assert not dated, (path.name, field.name, dated[:2])


TASK_INPUTS = ("specs", "town", "driver_model", "source_path")   # what every stored study names
# an absolute path in a text: a slash that begins no URL, fraction or unit (m/s), two segments or more
ABSOLUTE = re.compile(rb"(?<![\w.:/])/[\w.-]+/")


def assert_task_inputs(package: Path, keys: tuple[str, ...] = TASK_INPUTS) -> None:
    """The package holds every input its study_config.json names (`keys`: by default the specs, the
    town, the driver model and the config file; and any policy file, population or route file),
    where the config names it, each listed in SHA256SUMS with its hash and in the README."""
    config = json.loads((package / "study_config.json").read_text())
    named = [config[key] for key in keys]
    for key in ("conditions", "routes", "robust_population", "driver_population"):
        value = config.get(key) or []
        named += [v for v in (value if isinstance(value, list) else [value]) if v.startswith("inputs/")]
    flat = [p for value in named for p in (value if isinstance(value, list) else [value])]
    assert flat and all(p.startswith("inputs/") and (package / p).is_file() for p in flat), flat
    sums = dict(reversed(line.split("  ", 1)) for line in (package / "SHA256SUMS").read_text().splitlines())
    readme = (package / "README.md").read_text()
    copied = sorted(p.relative_to(package).as_posix() for p in (package / "inputs").rglob("*") if p.is_file())
    assert set(flat) <= set(copied)
    for path in copied:
        assert sums[path] == hashlib.sha256((package / path).read_bytes()).hexdigest(), path
        assert f"`{path}`" in readme, path


def assert_nothing_identifying(package: Path, words: list[str]) -> None:
    """No file of the package, read as bytes, holds any of `words` (paths of the lab's disk, names,
    tokens) or, being text, an absolute path."""
    for path in sorted(p for p in package.rglob("*") if p.is_file()):
        data = path.read_bytes()
        found = [word for word in words if word.encode() in data]
        assert not found, (path, found)
        if path.suffix in (".json", ".toml", ".md", ".txt", ".xml") or path.name == "SHA256SUMS":
            assert not ABSOLUTE.findall(data), (path, ABSOLUTE.findall(data)[:3])
