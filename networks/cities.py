"""The packaged cities: the RESCO Ingolstadt scenario (21 signals) of sumo-rl as the town `city`, and
RouteRL's OpenStreetMap net of Csömör as the town `csomor`.

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
`routes = ["city"]`).

`csomor` ships with the package: the plain-XML description of the net (networks/data/csomor/,
gzipped). On first use netconvert (the eclipse-sumo wheel's) builds the net from it and the net is
imported by the same rule, into a cache folder whose name holds a hash of the plain files' content,
the netconvert command, the SUMO version and the import's options. It has no demand of its own:
background traffic comes from randomTrips.py (`--background`). Licence and provenance of the data:
docs/cities.md and networks/data/csomor/README.md.
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import importlib.metadata
import importlib.util
import shutil
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np

from trustroute.core.cache import TOWNS as TOWNS_CACHE
from trustroute.core.cache import cache_dir
from trustroute.core.errors import InputError
from trustroute.core.packaged import PackagedKind
from trustroute.core.validation import read_input_bytes
from trustroute.networks.osm_convert import GENERATED_HEADER
from trustroute.networks.road_geometry import file_sha256
from trustroute.networks.sumo_net import find_binary
from trustroute.networks.town import Town, load_town
from trustroute.networks.town_import import import_town

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


@functools.cache
def importer_fingerprint() -> str:
    """A hash of the importer's own source code (read once per process: it cannot change there)."""
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


def built_folder(stem: str, key: str, town_file: str, build: Callable[[Path], None]) -> Path:
    """The cache folder `towns/<stem>-<key[:16]>` holding `town_file`, made by `build(folder)` when
    missing."""
    folder = cache_dir(TOWNS_CACHE) / f"{stem}-{key[:16]}"
    if (folder / town_file).is_file():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    # Built in a folder of its own and renamed into place: a concurrent build (study workers) or an
    # interrupted one never leaves a half-written town where a reader finds it.
    work = Path(tempfile.mkdtemp(prefix=f".{stem}-", dir=folder.parent))
    try:
        build(work)
        try:
            work.rename(folder)
        except OSError:
            if not (folder / town_file).is_file():   # not another process's finished build
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return folder


def city_folder() -> Path:
    """The cache folder holding the city's town, net and routes, imported when missing."""
    net, routes = scenario_files()
    key = hashlib.sha256(f"{IMPORT_OPTIONS}\n{importer_fingerprint()}\n{file_sha256(net)}\n"
                         f"{file_sha256(routes)}".encode()).hexdigest()
    return built_folder(SCENARIO, key, CITY_TOWN_FILE, lambda work: _import_city(net, routes, work))


def _import_city(net: Path, routes: Path, folder: Path) -> None:
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


CSOMOR = "csomor"
CSOMOR_DATA = Path(__file__).resolve().parent / "data" / "csomor"
CSOMOR_TOWN_FILE = "csomor.json"
CSOMOR_NET_FILE = "csomor.net.xml"
# netconvert's option for each plain-XML file of the net, in the order of the command.
CSOMOR_PLAIN = {"nod": "-n", "edg": "-e", "con": "-x", "tll": "-i", "typ": "-t"}


def csomor_plain_files() -> dict[str, Path]:
    """The packaged plain-XML files of Csömör's net by kind ("nod", ...), gzipped."""
    return {kind: CSOMOR_DATA / f"csomor.{kind}.xml.gz" for kind in CSOMOR_PLAIN}


def csomor_netconvert_command(binary: str, plain: dict[str, Path], output: Path) -> list[str]:
    """netconvert's command building the net from the unpacked plain files."""
    command = [binary]
    for kind, option in CSOMOR_PLAIN.items():
        command += [option, str(plain[kind])]
    return [*command, "-o", str(output)]


def csomor_folder() -> Path:
    """The cache folder holding Csömör's town and net, built and imported when missing."""
    contents = [hashlib.sha256(gzip.decompress(path.read_bytes())).hexdigest()
                for path in csomor_plain_files().values()]
    plain_names = {kind: Path(kind) for kind in CSOMOR_PLAIN}
    recipe = " ".join(csomor_netconvert_command("netconvert", plain_names, Path("net")))
    sumo_version = importlib.metadata.version("eclipse-sumo")
    parts = [IMPORT_OPTIONS, importer_fingerprint(), recipe, sumo_version, *contents]
    key = hashlib.sha256("\n".join(parts).encode()).hexdigest()
    return built_folder(CSOMOR, key, CSOMOR_TOWN_FILE, _build_csomor)


def _build_csomor(folder: Path) -> None:
    plain = {}
    for kind, packed in csomor_plain_files().items():
        plain[kind] = folder / packed.name.removesuffix(".gz")
        plain[kind].write_bytes(gzip.decompress(packed.read_bytes()))
    net = folder / CSOMOR_NET_FILE
    result = subprocess.run(csomor_netconvert_command(find_binary("netconvert"), plain, net),
                            capture_output=True, text=True, check=False)
    if result.returncode != 0 or not net.is_file():
        last = (result.stderr.strip().splitlines() or ["no output"])[-1]
        raise InputError(str(CSOMOR_DATA), "", f"netconvert could not build the net of Csömör ({last})",
                         "reinstall the package with its pinned eclipse-sumo wheel (pip install -e .)")
    for path in plain.values():
        path.unlink()
    # Without netconvert's dated header: the same plain files give the same net (and content hash).
    net.write_bytes(GENERATED_HEADER.sub(b"", net.read_bytes(), count=1))
    import_town(net, folder / CSOMOR_TOWN_FILE, rng=np.random.default_rng(CITY_INCIDENT_SEED),
                incident_seed=CITY_INCIDENT_SEED)


def csomor_town_path() -> Path:
    """The town file of `csomor` (built on first use)."""
    return csomor_folder() / CSOMOR_TOWN_FILE


# Route files of background traffic by name: the city's demand (networks/data ships none).
ROUTES = PackagedKind("route file", Path(__file__).parent / "data", ".rou.xml",
                      built={CITY: city_routes_path})
ROUTE_FILE_BYTES = 1 << 30  # a city's demand of a day is tens of MB
ROUTE_FILE_FIX = "pass a .rou.xml / .trips.xml (gzip allowed) written for this net"


def read_route_file(path: str | Path) -> ET.ElementTree:
    """A SUMO route file (gzipped when its name ends in .gz) parsed as XML, through the guarded
    reader; InputError naming it when it cannot be read or parsed. The one reader of route files:
    the study config's check, `trustroute run --routes` and the episodes' background traffic
    (harness/simulation/background.py) all parse them here."""
    data = read_input_bytes(path, "SUMO route file", ROUTE_FILE_BYTES, fix=ROUTE_FILE_FIX)
    try:
        if str(path).endswith(".gz"):
            data = gzip.decompress(data)
        return ET.ElementTree(ET.fromstring(data))
    except (OSError, EOFError, ET.ParseError) as exc:
        raise InputError(str(path), "", f"not a readable SUMO route file ({exc})", ROUTE_FILE_FIX) from None


# The packaged town whose net each packaged route set drives: its routes are edges of that net only.
ROUTE_TOWNS: dict[str, str] = {CITY: CITY}


def route_set_town(value: str, resolved: str | Path) -> str | None:
    """The packaged town of the route file given as `value` (`resolved`: the file it names) when it
    is a packaged route set, else None (a route file of the user's)."""
    stem = value.removesuffix(ROUTES.suffix)
    if stem not in ROUTE_TOWNS or Path(value).name != value:
        return None
    packaged = ROUTES.path(stem)
    same = packaged is not None and packaged.resolve() == Path(resolved).resolve()
    return ROUTE_TOWNS[stem] if same else None


def check_route_set_town(value: str, resolved: str | Path, town: Town, source: str, place: str,
                         fix: str) -> None:
    """A packaged route set runs on its own town's net only (SUMO would stop at the first route's
    unknown edge): when `value` is one and `town` drives another net, InputError with `fix`
    ("{town}" in it: the route set's town)."""
    owner = route_set_town(value, resolved)
    if owner is None:
        return
    own_net, net = load_town(owner).sumo_net, town.sumo_net
    if net is None or own_net is None or net.sha256 != own_net.sha256:
        raise InputError(source, place, f"the packaged route set {value!r} is traffic on the town {owner}'s "
                         f"roads, not on those of the town driven ({town.source_path})",
                         fix.format(town=owner))
