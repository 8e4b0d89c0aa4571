"""The layout of a package `trustroute export` writes (docs/live_studies.md, "Export"), as far as
the readers of a study need it: to know a package when one is passed for a study directory, to
check it against its checksums, and to find its tables.

A package holds a study's tables in a folder of their own beside the config it was run with, and no
study manifest: it is no study directory. `trustroute analyze` reads it all the same, from the
package's manifest (`PACKAGE_MANIFEST_FILE`: the study manifest's keys, docs/dataset.md, with what
would identify a participant or the lab left out), once every file `SHA256SUMS` lists has its
checksum; the commands that need more than the tables (`replay`, `fit`, `plan --pilot`, `export`)
say it is a package.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.core.validation import read_input_text

PACKAGE_TABLES_DIR = "tables"
PACKAGE_CONFIG_FILE = "study_config.json"
PACKAGE_MANIFEST_FILE = "study_manifest.json"   # the manifest, as far as a package holds it
SUMS_FILE = "SHA256SUMS"                         # `sha256sum -c` format: "<hex>  <relative path>"
PACKAGE_FIX = ("this is a package `trustroute export` wrote, not a study directory: `trustroute "
               "analyze` reads it, but replay, fit or export the study directory it was exported from; "
               f"the package's tables are Parquet files under {PACKAGE_TABLES_DIR}/, their columns in "
               "codebook.md")
TAMPERED_FIX = "get the package again from where it was published (it must match its SHA256SUMS)"


def is_package(folder: Path) -> bool:
    """Whether `folder` is a package (it has a package's config and tables folder)."""
    return (Path(folder) / PACKAGE_CONFIG_FILE).is_file() and (Path(folder) / PACKAGE_TABLES_DIR).is_dir()


def tables_folder(folder: Path) -> Path:
    """The folder of the tables of a study directory (itself), or of a package (its tables/)."""
    return Path(folder, *[PACKAGE_TABLES_DIR] * is_package(folder))


def table_path(folder: Path, file_name: str) -> Path:
    """The table file `file_name` of a study directory, or of a package (in its tables/ folder)."""
    return tables_folder(folder) / file_name


def package_fix(folder: Path) -> str | None:
    """The fix to show for `folder` passed as a study directory when it is a package, else None."""
    return PACKAGE_FIX if is_package(folder) else None


def sha256_of(path: Path) -> str:
    """The file's SHA-256 (hex), read in blocks: a table may be larger than memory holds at ease."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as source:
        for block in iter(lambda: source.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def verify_package(folder: Path) -> bool:
    """Whether `folder` is a package (`is_package`) whose every file `SHA256SUMS` lists has that
    SHA-256, the package's manifest one of them; False for no package; InputError naming the first
    file that is not so."""
    folder = Path(folder)
    if not is_package(folder):
        return False
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
    return True
