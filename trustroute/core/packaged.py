"""The packaged input files and the one rule that finds one by name.

An argument that names an input (SPEC, TOWN, DRIVER, POPULATION; on the command line, in the API,
in a study config and in the gym environment) is a path or the name of a packaged file: an
existing file wins; otherwise a bare name ("phi1" or "phi1.toml") names the packaged file of that
stem. Each kind is a `PackagedKind`, declared by the lowest layer that owns its folder: the specs
here (`trustroute/core/specs/`), the towns in networks/town.py (`networks/data/`), the driver
models and populations in participants (`participants/data/`). A kind may also name inputs that
are built on first use rather than shipped (`built`: the town `city`, imported from an optional
extra's package data, and the town `csomor`, built from packaged plain XML; networks/cities.py).
Hints list the packaged names, which exist wherever the package is installed (a repository path
such as specs/phi1.toml does not).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from trustroute.core.errors import InputError

PACKAGED_SPECS = Path(__file__).resolve().parent / "specs"


@dataclass(frozen=True)
class PackagedKind:
    """One kind of packaged input: its files are `folder/<stem><suffix>` whose stem starts with
    `prefix` and has no dot (a "x.fit.json" beside "x.json" is not an input of the kind), and the
    `built` names, each with the function that builds its file on first use and returns its path
    (or raises InputError naming the fix, e.g. an optional extra to install). `built` is filled by
    the module that builds them when that module sits above the kind's owner (networks/__init__.py
    registers the towns `city` and `csomor`)."""

    what: str          # "spec", "town", "driver model", "driver population"
    folder: Path
    suffix: str        # ".toml" or ".json"
    prefix: str = ""
    built: Mapping[str, Callable[[], Path]] = field(default_factory=dict, compare=False, hash=False)

    def names(self) -> list[str]:
        """The packaged names, sorted."""
        shipped = [] if not self.folder.is_dir() else [
            p.name[: -len(self.suffix)] for p in self.folder.glob(f"{self.prefix}*{self.suffix}")
            if "." not in p.name[: -len(self.suffix)]]
        return sorted({*shipped, *self.built})

    def path(self, name: str | Path) -> Path | None:
        """The packaged file called `name` (a bare name, with or without the suffix), or None; a
        built name's file is built here when it is not yet."""
        text = str(name)
        if not text or Path(text).name != text:   # a path with a folder is never a packaged name
            return None
        stem = text[: -len(self.suffix)] if text.endswith(self.suffix) else text
        if stem in self.built:
            return self.built[stem]()
        return self.folder / f"{stem}{self.suffix}" if stem in self.names() else None

    def resolve(self, value: str | Path, base: Path | None = None) -> Path:
        """The file `value` names: an existing file, else the packaged file of that name, else
        `value` unchanged (its reader then says it cannot be read, with `fix()`). `base`: the folder
        a relative `value` is read in (a population's `model_file` is relative to the population
        file's folder), else the current directory."""
        if str(value) == "":   # Path("") is the current directory
            raise InputError(self.what, "", f"the {self.what} name is empty", self.fix())
        path = Path(value)
        if base is not None and not path.is_absolute():
            path = base / path
        if path.is_file():
            return path
        return self.path(value) or path

    def ships(self, path: str | Path) -> bool:
        """Whether `path` is one of the kind's shipped files: a file in its folder, however the path
        reaches it (the repository's specs/ links to the packaged folder)."""
        try:
            path = Path(path).resolve()
        except OSError:
            return False
        return path.parent == self.folder.resolve() and path.is_file()

    def fix(self, given: str = "") -> str:
        """The hint for a missing input: a file, or one of the packaged names (which exist).
        `given` is how the command line takes it: an option ("--town": "with --town") or a
        positional argument ("TOWN": "as TOWN"); "" names neither (a config key, the API)."""
        names = ", ".join(self.names())
        return (f"pass an existing {self.what} file{passed_how(given)} or a packaged {self.what} "
                f"name ({names})")


def passed_how(given: str) -> str:
    """How the command line takes an input, for a hint: " with --town" for an option, " as TOWN"
    for a positional argument, "" for neither (a config key, the API)."""
    return "" if not given else f" with {given}" if given.startswith("-") else f" as {given}"


SPECS = PackagedKind("spec", PACKAGED_SPECS, ".toml")


def packaged_spec_path(name: str) -> Path | None:
    """The packaged spec called `name` ("phi1" or "phi1.toml"), or None when there is none."""
    return SPECS.path(name)


# The packaged specs written for a packaged town other than the default: their waypoints name
# that town's junctions.
SPEC_TOWNS: dict[str, str] = {"city5": "city", "csomor5": "csomor"}


def packaged_spec_names(town: str | None = None) -> list[str]:
    """The names of the packaged specs written for the packaged town `town` (None: the default
    town), sorted."""
    return [name for name in SPECS.names() if SPEC_TOWNS.get(name) == town]
