"""Type-check the trustroute namespace with mypy: `python -m tests.typecheck` (run by `make lint`).

The namespace's subpackages live in top-level folders (pyproject's package-dir), which mypy cannot
map; the check runs on a temporary tree of symlinks laid out as the installed package is."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def package_tree(root: Path) -> Path:
    """root/trustroute laid out as the installed package, every entry a symlink into the repo."""
    package_dir = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    top = root / "trustroute"
    top.mkdir()
    for entry in (REPO / package_dir["trustroute"]).iterdir():
        if entry.name != "__pycache__":
            (top / entry.name).symlink_to(entry)
    for package, folder in package_dir.items():
        if package != "trustroute":
            (top / package.removeprefix("trustroute.")).symlink_to(REPO / folder)
    return top


def run_mypy() -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as tmp:
        package_tree(Path(tmp))
        return subprocess.run(
            [sys.executable, "-m", "mypy", "--config-file", str(REPO / "pyproject.toml"),
             "--cache-dir", str(REPO / ".mypy_cache"), "trustroute"],
            cwd=tmp, capture_output=True, text=True)


if __name__ == "__main__":
    done = run_mypy()
    out = done.stdout
    for package in ("analysis", "harness", "networks", "participants", "policies"):
        out = out.replace(f"trustroute/{package}/", f"{package}/")
    sys.stdout.write(out)
    sys.stderr.write(done.stderr)
    raise SystemExit(done.returncode)
