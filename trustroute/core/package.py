"""The layout of a package `trustroute export` writes (docs/live_studies.md, "Export"), as far as
the readers of a study need it: to know a package when one is passed for a study directory.

A package holds a study's tables in a folder of their own beside the config it was run with, and no
manifest: it is no study directory, and the commands that read one (`analyze`, `replay`, `fit`,
`plan --pilot`, `export`) say so instead of asking for a study to be run.
"""

from __future__ import annotations

from pathlib import Path

PACKAGE_TABLES_DIR = "tables"
PACKAGE_CONFIG_FILE = "study_config.json"
PACKAGE_FIX = ("this is a package `trustroute export` wrote, not a study directory: analyse, replay or fit "
               "the study directory it was exported from; the package's tables are Parquet files under "
               f"{PACKAGE_TABLES_DIR}/, their columns in codebook.md")


def package_fix(folder: Path) -> str | None:
    """The fix to show for `folder` passed as a study directory when it is a package (it has a
    package's config and tables folder), else None."""
    packaged = (Path(folder) / PACKAGE_CONFIG_FILE).is_file() and (Path(folder) / PACKAGE_TABLES_DIR).is_dir()
    return PACKAGE_FIX if packaged else None
