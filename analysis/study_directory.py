"""Reading a consolidated study directory: its manifest, episodes and roads (through
trustroute.core.dataset), and the town, driver model and specs its config names (the directory's
own copies, wherever it has been copied).

Every analysis of a study starts here: the study tables, the real-study analysis, fitting driver
models to the logs, and the export. `load_study` reads the tables against the study's inputs: the
trust levels of its driver model (trustroute.core.dataset checks them with the other values), and
here what only the inputs know: every road is one of the town's, every incident one of the driver
model's, every episode's spec one of the study's.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from trustroute.core.dataset import (
    EPISODES_FILE,
    REBUILD_FIX,
    ROADS_FILE,
    check_allowed,
    read_episodes,
    read_manifest,
    read_roads,
)
from trustroute.core.errors import InputError
from trustroute.core.package import PACKAGE_TABLE_FIX, is_package, tables_folder, verify_package
from trustroute.harness.study.context import load_study_inputs
from trustroute.harness.study.inputs import (
    manifest_wording,
    not_stored_nor_absolute,
    relocated_config,
    spec_paths,
    verify_inputs,
)
from trustroute.networks.town import Town
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.logic.spec import Spec

# what `load_study` reads: (manifest, episodes, roads)
LoadedStudy = tuple[dict, pd.DataFrame, pd.DataFrame]


def load_study(study_dir: Path, package: bool = False) -> LoadedStudy:
    """(manifest, episodes, roads) of a consolidated study, read through trustroute.core.dataset;
    the manifest's config names the study directory's own copies of its inputs (absolute paths
    where the directory lies, harness/study/inputs.py), checked against their hashes, and the
    tables are checked against those inputs (module docstring). `package`: or of a package
    `trustroute export` wrote, checked against its checksums (`verify_package`), which cover its
    manifest and its inputs/ as well: what its manifest records of its inputs is checked against
    those checksums, no file hashed a second time."""
    study_dir = Path(study_dir)
    checked = verify_package(study_dir) if package else None
    manifest = read_manifest(study_dir, checked is not None)
    verify_inputs(manifest, study_dir, checked)
    manifest = {**manifest, "config": relocated_config(manifest.get("config") or {}, study_dir)}
    town, driver, specs = study_inputs(manifest, study_dir)
    episodes = read_episodes(study_dir, trust_levels=driver.trust_levels)
    roads = read_roads(study_dir, trust_levels=driver.trust_levels)
    check_logged_inputs(study_dir, episodes, roads, (town, driver, specs))
    return manifest, episodes, roads


def check_logged_inputs(study_dir: Path, episodes: pd.DataFrame, roads: pd.DataFrame,
                        inputs: tuple[Town, DriverModel, dict[str, Spec]]) -> None:
    """The tables name only what the study's inputs have, or InputError naming the file, column and
    first row that does not: roads of the town, incidents of the driver model, specs of the study."""
    town, driver, specs = inputs
    packaged = is_package(study_dir)
    tables, fix = tables_folder(study_dir, packaged), PACKAGE_TABLE_FIX if packaged else REBUILD_FIX
    roads_file, episodes_file = (str(tables / name) for name in (ROADS_FILE, EPISODES_FILE))
    check_allowed(episodes["spec"], specs, episodes_file, "spec",
                  f"one of the study's specs ({', '.join(specs)})", fix)
    check_allowed(roads["directed_road"], town.states, roads_file, "directed_road",
                  "a road of the study's town", fix)
    check_allowed(roads["incident"], driver.incident_types, roads_file, "incident",
                  f"an incident type of the study's driver model ({', '.join(driver.incident_types)})", fix)


def study_inputs(manifest: dict, study_dir: Path):
    """(town, nominal driver model, {spec name: Spec}) named by the config of the study in
    `study_dir` (its manifest as `load_study` returns it), loaded as the study loaded them
    (harness/study/context.py, `load_study_inputs`); an input that cannot be loaded is an
    InputError naming the manifest and the config key."""
    config = manifest["config"]
    said = manifest_wording(study_dir)
    shown, fix = str(Path(study_dir) / said.manifest), said.config_fix
    town = _recorded_input(config.get("town"), "town", shown, fix)
    driver = _recorded_input(config.get("driver_model"), "driver model", shown, fix)
    specs = spec_paths(manifest, study_dir)
    keyed = [("config.town", town), ("config.driver_model", driver),
             *((f"config.specs[{i}]", str(p)) for i, p in enumerate(specs))]
    try:
        return load_study_inputs(town, driver, specs)
    except InputError as exc:
        key = next((k for k, p in keyed if p is not None and Path(exc.source) == Path(p)), None)
        if key is None:
            raise
        where = f"{exc.place}: " if exc.place else ""
        raise InputError(shown, key, f"cannot load {exc.source} ({where}{exc.problem})", exc.fix) from None


def _recorded_input(path: str | None, what: str, shown: str, fix: str) -> str | None:
    """A town or driver model path the config records (`shown`: the manifest, `fix`: the fix of an
    edited one): one of the study's stored copies, or the absolute path of a study made before its
    inputs were stored; InputError for any other path (never read relative to where the command
    runs), or when it is gone (no option of a command can stand in)."""
    key = f"config.{what.replace(' ', '_')}"
    if path is not None and not Path(path).is_absolute():
        raise InputError(shown, key, not_stored_nor_absolute(what, path), fix)
    if path is not None and not Path(path).is_file():
        raise InputError(shown, key,
                         f"the study's {what} {path} is gone, and this study directory holds no copy of "
                         "its inputs (it was made before studies stored them)",
                         f"restore {path}, or analyse the study where it was made")
    return path
