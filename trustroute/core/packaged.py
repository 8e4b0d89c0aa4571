"""The packaged input files and the one rule that finds one by name.

An argument that names an input (SPEC, TOWN, DRIVER, POPULATION; on the command line, in the API,
in a study config and in the gym environment) is a path or the name of a packaged file: an
existing file wins; otherwise a bare name ("phi1" or "phi1.toml") names the packaged file of that
stem. Each kind is a `PackagedKind`, declared by the lowest layer that owns its folder: the specs
here (`trustroute/core/specs/`), the towns in networks/town.py (`networks/data/`), the driver
models and populations in participants (`participants/data/`). Hints list the packaged names,
which exist wherever the package is installed (a repository path such as specs/phi1.toml does not).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

PACKAGED_SPECS = Path(__file__).resolve().parent / "specs"


@dataclass(frozen=True)
class PackagedKind:
    """One kind of packaged input: its files are `folder/<stem><suffix>` whose stem starts with
    `prefix` and has no dot (a "x.fit.json" beside "x.json" is not an input of the kind)."""

    what: str          # "spec", "town", "driver model", "driver population"
    folder: Path
    suffix: str        # ".toml" or ".json"
    prefix: str = ""

    def names(self) -> list[str]:
        """The packaged names, sorted."""
        if not self.folder.is_dir():
            return []
        return sorted(p.name[: -len(self.suffix)] for p in self.folder.glob(f"{self.prefix}*{self.suffix}")
                      if "." not in p.name[: -len(self.suffix)])

    def path(self, name: str | Path) -> Path | None:
        """The packaged file called `name` (a bare name, with or without the suffix), or None."""
        text = str(name)
        if not text or Path(text).name != text:   # a path with a folder is never a packaged name
            return None
        stem = text[: -len(self.suffix)] if text.endswith(self.suffix) else text
        return self.folder / f"{stem}{self.suffix}" if stem in self.names() else None

    def resolve(self, value: str | Path) -> Path:
        """The file `value` names: an existing file, else the packaged file of that name, else
        `value` unchanged (its reader then says it cannot be read, with `fix()`)."""
        path = Path(value)
        if path.is_file():
            return path
        return self.path(value) or path

    def fix(self, option: str = "") -> str:
        """The hint for a missing input: a file, or one of the packaged names (which exist)."""
        names = ", ".join(self.names())
        given = f" with {option}" if option else ""
        return f"pass an existing {self.what} file{given} or a packaged {self.what} name ({names})"


SPECS = PackagedKind("spec", PACKAGED_SPECS, ".toml")


def packaged_spec_path(name: str) -> Path | None:
    """The packaged spec called `name` ("phi1" or "phi1.toml"), or None when there is none."""
    return SPECS.path(name)


def packaged_spec_names() -> list[str]:
    """The names of the packaged specs, sorted."""
    return SPECS.names()
