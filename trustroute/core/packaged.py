"""The packaged spec files (`trustroute/core/specs/`) and the one rule that finds one by name."""

from __future__ import annotations

from pathlib import Path

PACKAGED_SPECS = Path(__file__).resolve().parent / "specs"


def packaged_spec_path(name: str) -> Path | None:
    """The packaged spec called `name` ("phi1" or "phi1.toml"), or None when there is none."""
    stem = Path(name).name
    candidate = PACKAGED_SPECS / (stem if stem.endswith(".toml") else f"{stem}.toml")
    return candidate if candidate.is_file() else None


def packaged_spec_names() -> list[str]:
    """The names of the packaged specs, sorted."""
    return sorted(p.stem for p in PACKAGED_SPECS.glob("*.toml")) if PACKAGED_SPECS.is_dir() else []
