"""pyproject's explicit package list covers every package folder: `pip install .` ships them all."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def package_folders(package_dir: dict[str, str]) -> set[str]:
    found = set()
    for top, folder in package_dir.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            relative = init.parent.relative_to(ROOT / folder)
            found.add(top if not relative.parts else ".".join((top, *relative.parts)))
    return found


def test_every_package_folder_is_listed_and_every_listed_package_exists():
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    found = package_folders(setuptools["package-dir"])
    assert found - listed == set(), "package folders missing from [tool.setuptools] packages"
    assert listed - found == set(), "listed packages without a folder"
