"""The layout of a package `trustroute export` writes (docs/live_studies.md, "Export"), as far as
the readers of a study need it: to know a package when one is passed for a study directory, to
check it against its checksums, and to find its tables and read them by the schemas the export
writes them with (`package_schema`: no wall-clock time, and a live study's without its seeds).

A package holds a study's tables in a folder of their own beside the config it was run with, and no
study manifest: it is no study directory. `trustroute analyze` reads it all the same, from the
package's manifest (`PACKAGE_MANIFEST_FILE`: the study manifest's keys, docs/dataset.md, with what
would identify a participant or the lab left out), once every file `SHA256SUMS` lists has its
checksum; the commands that need more than the tables (`replay`, `fit`, `plan --pilot`, `export`)
say it is a package. A run writes nothing into a package (`package_holding`): a study directory
there is refused, and a policy cache there is the user's.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import TYPE_CHECKING

from trustroute.core.errors import InputError
from trustroute.core.validation import read_input_text

if TYPE_CHECKING:
    import pyarrow as pa

PACKAGE_TABLES_DIR = "tables"
PACKAGE_CONFIG_FILE = "study_config.json"
PACKAGE_MANIFEST_FILE = "study_manifest.json"   # the manifest, as far as a package holds it
SUMS_FILE = "SHA256SUMS"                         # `sha256sum -c` format: "<hex>  <relative path>"
PACKAGE_FIX = ("this is a package `trustroute export` wrote, not a study directory: `trustroute "
               "analyze` reads it, but replay, fit or export the study directory it was exported from; "
               f"the package's tables are Parquet files under {PACKAGE_TABLES_DIR}/, their columns in "
               "codebook.md")
TAMPERED_FIX = "get the package again from where it was published (it must match its SHA256SUMS)"
# the fix of a package's table that is not as this trustroute exports it: it exported no such table
PACKAGE_TABLE_FIX = ("analyse the package with the trustroute that exported it (its versions.json names "
                     "the version), or get the package again from where it was published")
# table -> wall-clock column -> the column an export writes in its place (harness/study/export.py)
EXPORTED_TIMES: dict[str, dict[str, str]] = {
    "attempts": {"started_utc": "started_s", "ended_utc": "ended_s"},
    "questionnaires": {"answered_utc": "answered_s"},
}
# Columns a package of a study with people leaves out, with the config keys that go with them: an
# episode's seed is drawn from the study's seed and the participant's number (harness/study/plan.py),
# so both together would give each pseudonym's number, the order of enrolment, back. A simulated
# study keeps them (it has no one to hide, and they reproduce it).
WITHOUT_PEOPLE_SEEDS: dict[str, tuple[str, ...]] = {"episodes": ("seed",)}
CONFIG_WITHOUT_PEOPLE_SEEDS: tuple[str, ...] = ("seed",)


def is_package(folder: Path) -> bool:
    """Whether `folder` is a package (it has a package's config and tables folder)."""
    return (Path(folder) / PACKAGE_CONFIG_FILE).is_file() and (Path(folder) / PACKAGE_TABLES_DIR).is_dir()


def package_holding(path: Path) -> Path | None:
    """The package `path` lies in: itself or the nearest folder above it that `is_package`, else
    None. A package is published read-only, so a run writes nothing under it (a copy of one is a
    package too)."""
    path = Path(path).resolve()
    return next((folder for folder in (path, *path.parents) if is_package(folder)), None)


def check_outside_package(path: Path, option: str, what: str) -> None:
    """InputError naming the package when the `what` (a file or folder) `path`, given by `option`,
    lies in one."""
    package = package_holding(path)
    if package is not None:
        raise InputError(str(path), option, f"the {what} lies in the package {package}, which is "
                         "published read-only: a run writes nothing into it",
                         f"pass {option} a path outside the package")


def outside_packages(folder: str | None) -> str | None:
    """A study config's policy cache `folder` (None: the user's cache), the user's cache when it lies
    in a package: a config file a package holds names a cache beside itself (a study re-run from
    it), which the run would fill there. The cache is no part of a study's identity (its config's
    `content_hash`), so the run's data are the same."""
    return None if folder is None or package_holding(Path(folder)) is not None else folder


def tables_folder(folder: Path, packaged: bool | None = None) -> Path:
    """The folder of the tables of a study directory (itself), or of a package (its tables/);
    `packaged`: whether `folder` is a package (`is_package`), when the caller has asked."""
    packaged = is_package(folder) if packaged is None else packaged
    return Path(folder, *[PACKAGE_TABLES_DIR] * packaged)


def table_path(folder: Path, file_name: str) -> Path:
    """The table file `file_name` of a study directory, or of a package (in its tables/ folder)."""
    return tables_folder(folder) / file_name


def package_schema(schema: pa.Schema, table: str, people: bool = False) -> pa.Schema:
    """The schema `schema` of the study table `table` (a key of dataset.TABLES) as a package holds
    it: its wall-clock columns as seconds, and (`people`: a live study's package) without the
    columns of WITHOUT_PEOPLE_SEEDS."""
    import pyarrow as pa  # here, not at the top: every output check reads this module's rules

    for column in WITHOUT_PEOPLE_SEEDS.get(table, ()) if people else ():
        schema = schema.remove(schema.get_field_index(column))
    for column, seconds in EXPORTED_TIMES.get(table, {}).items():
        index = schema.get_field_index(column)
        schema = schema.set(index, pa.field(seconds, pa.float64(), nullable=schema.field(index).nullable))
    return schema


def package_schemas(schema: pa.Schema, table: str) -> tuple[pa.Schema, ...]:
    """The schemas a package's table `table` of study schema `schema` may have: as a simulated
    study's package holds it, and as a live study's does (`package_schema`)."""
    return package_schema(schema, table), package_schema(schema, table, people=True)


def package_fix(folder: Path) -> str | None:
    """The fix to show for `folder` passed as a study directory when it is a package, else None."""
    return PACKAGE_FIX if is_package(folder) else None


SHA256_HEX = re.compile(r"[0-9a-f]{64}")   # a SHA-256 as `sha256_of` writes it


def sha256_of(path: Path) -> str:
    """The file's SHA-256 (hex), read in blocks: a table may be larger than memory holds at ease."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as source:
        for block in iter(lambda: source.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def verify_package(folder: Path) -> dict[str, str] | None:
    """The SHA-256 (hex) of each file `SHA256SUMS` lists of the package `folder` (`is_package`),
    by its path relative to the package, every one found to be the file's, the package's manifest
    one of them; None for no package; InputError naming the first file that is not so. The caller
    checks what the manifest records against these (harness/study/inputs.py, `verify_inputs`)
    rather than hashing a file again."""
    folder = Path(folder)
    if not is_package(folder):
        return None
    sums = folder / SUMS_FILE
    listed: dict[str, str] = {}
    lines = read_input_text(sums, "package checksums", fix=TAMPERED_FIX).splitlines()
    for number, line in enumerate(lines, 1):
        digest, _, name = line.partition("  ")
        if len(digest) != 64 or not name or Path(name).is_absolute() or ".." in Path(name).parts:
            raise InputError(str(sums), f"line {number}", "not `<SHA-256>  <file of the package>`",
                             TAMPERED_FIX)
        listed[name] = digest.lower()
    if PACKAGE_MANIFEST_FILE not in listed:
        raise InputError(str(folder / PACKAGE_MANIFEST_FILE), "", "the package has no manifest listed in "
                         f"{SUMS_FILE} (it was exported before packages held one)",
                         "export the study again with this trustroute")
    for name, digest in sorted(listed.items()):
        path = folder / name
        if not path.is_file():
            raise InputError(str(path), "", f"a file {SUMS_FILE} lists is missing", TAMPERED_FIX)
        try:
            actual = sha256_of(path)
        except OSError as error:
            raise InputError(str(path), "", f"cannot be read ({error.strerror})", TAMPERED_FIX) from None
        if actual != digest:
            raise InputError(str(path), "", f"its SHA-256 differs from the one in {SUMS_FILE}: the "
                             "package changed since it was exported", TAMPERED_FIX)
    return listed
