"""The packaged city: the RESCO Ingolstadt scenario (21 signals) of sumo-rl as the town `city`.

`city` is a packaged town name like the files of networks/data, but its net and its demand are the
package data of the optional extra `cities` (`pip install 'trustroute[cities]'`: sumo-rl, which
ships the RESCO scenarios under `sumo_rl/nets/RESCO/`). They are found without importing sumo_rl,
whose import needs SUMO_HOME. On first use the net is imported as `trustroute town import` does
(networks/town_import.py), with incidents drawn by the seeded rule (seed CITY_INCIDENT_SEED), and
the town is written into the cache (`towns/`, trustroute/core/cache.py) beside copies of the net and
the scenario's routes: the folder's name holds a hash of the net's and the routes' bytes, of
the import's options and of the importer's source, so the same scenario is imported once and a
changed one (or a changed importer) gives another town.
The routes are the packaged route file `city` (ROUTES: `trustroute run --routes city`, study key
`routes = ["city"]`). Licence and provenance of the data: docs/cities.md.
"""

from __future__ import annotations

import hashlib
import importlib.util
import shutil
import tempfile
from pathlib import Path

from trustroute.core.cache import TOWNS as TOWNS_CACHE
from trustroute.core.cache import cache_dir
from trustroute.core.errors import InputError
from trustroute.core.packaged import PackagedKind
from trustroute.networks.road_geometry import file_sha256

CITY = "city"
SCENARIO = "ingolstadt21"          # sumo-rl's nets/RESCO/<SCENARIO>/<SCENARIO>.net.xml and .rou.xml
CITY_INCIDENT_SEED = 7
CITY_TOWN_FILE = "city.json"
EXTRA_FIX = "pip install 'trustroute[cities]'"
# Part of the cache key: a change of the import's options or rule must give a folder of its own.
IMPORT_OPTIONS = f"trustroute town import --incident-seed {CITY_INCIDENT_SEED}; town format 1"
# The modules whose code decides what an import writes: their source is part of the cache key too,
# so a cached town never outlives a change of the importer's rule (turn restrictions, say).
IMPORTER_MODULES = ("sumo_import", "town_import", "road_geometry", "town_incidents", "town", "osm_convert")


def importer_fingerprint() -> str:
    """A hash of the importer's own source code."""
    digest = hashlib.sha256()
    for name in IMPORTER_MODULES:
        digest.update((Path(__file__).parent / f"{name}.py").read_bytes())
    return digest.hexdigest()


def scenario_files() -> tuple[Path, Path]:
    """The scenario's net and routes in the installed sumo-rl, or InputError naming the extra."""
    found = importlib.util.find_spec("sumo_rl")
    if found is None or not found.submodule_search_locations:
        raise InputError(CITY, "", "the packaged town and routes 'city' are the RESCO Ingolstadt scenario of "
                         "sumo-rl, which is not installed", EXTRA_FIX)
    folder = Path(list(found.submodule_search_locations)[0]) / "nets" / "RESCO" / SCENARIO
    net, routes = folder / f"{SCENARIO}.net.xml", folder / f"{SCENARIO}.rou.xml"
    for path in (net, routes):
        if not path.is_file():
            raise InputError(str(path), "", "the installed sumo-rl lacks the RESCO Ingolstadt scenario",
                             f"{EXTRA_FIX} (sumo-rl 1.4.5 ships it)")
    return net, routes


def city_folder() -> Path:
    """The cache folder holding the city's town, net and routes, imported when missing."""
    net, routes = scenario_files()
    key = hashlib.sha256(f"{IMPORT_OPTIONS}\n{importer_fingerprint()}\n{file_sha256(net)}\n"
                         f"{file_sha256(routes)}".encode()).hexdigest()
    folder = cache_dir(TOWNS_CACHE) / f"{SCENARIO}-{key[:16]}"
    if (folder / CITY_TOWN_FILE).is_file():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    # Built in a folder of its own and renamed into place: a concurrent build (study workers) or an
    # interrupted one never leaves a half-written town where a reader finds it.
    work = Path(tempfile.mkdtemp(prefix=f".{SCENARIO}-", dir=folder.parent))
    try:
        _import_city(net, routes, work)
        try:
            work.rename(folder)
        except OSError:
            if not (folder / CITY_TOWN_FILE).is_file():   # not another process's finished build
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return folder


def _import_city(net: Path, routes: Path, folder: Path) -> None:
    import numpy as np

    from trustroute.networks.town_import import import_town

    shutil.copyfile(net, folder / net.name)
    shutil.copyfile(routes, folder / routes.name)
    import_town(folder / net.name, folder / CITY_TOWN_FILE, rng=np.random.default_rng(CITY_INCIDENT_SEED),
                incident_seed=CITY_INCIDENT_SEED)


def city_town_path() -> Path:
    """The town file of `city` (built on first use)."""
    return city_folder() / CITY_TOWN_FILE


def city_routes_path() -> Path:
    """The scenario's own demand on the city's net: 4,283 passenger-car trips over one hour."""
    return city_folder() / f"{SCENARIO}.rou.xml"


# Route files of background traffic by name: the city's demand (networks/data ships none).
ROUTES = PackagedKind("route file", Path(__file__).parent / "data", ".rou.xml",
                      built={CITY: city_routes_path})
