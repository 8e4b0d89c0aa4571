"""OpenStreetMap extracts as SUMO nets: the eclipse-sumo wheel's netconvert with the options an
OSM import needs, and a written net that is the same bytes every time.

The options (`OSM_OPTIONS`): `--opposites.guess` declares the two directions of a street opposite
each other, so traffic can overtake through the oncoming lane; `--junctions.join` merges the
clusters of nodes OSM draws at one crossing into one junction; `--geometry.remove` merges edges
split only by shape nodes; roundabouts, ramps and traffic lights are guessed as OSM tags them;
`--output.street-names` keeps the street names the town's roads are named after.
netconvert heads its output with a comment holding the time and the file paths; it is taken out,
so converting the same extract twice gives the same net (and the same content hash).
"""

from __future__ import annotations

import os
import re
import subprocess
import tempfile
from pathlib import Path

from trustroute.core.errors import InputError
from trustroute.networks.sumo_net import find_binary
from trustroute.networks.town import NET_SUFFIXES, OSM_SUFFIXES

OSM_OPTIONS: tuple[str, ...] = (
    "--opposites.guess", "--junctions.join", "--geometry.remove", "--roundabouts.guess",
    "--ramps.guess", "--tls.guess-signals", "--tls.discard-simple", "--tls.join",
    "--output.street-names",
)
GENERATED_HEADER = re.compile(rb"<!-- generated on .*?-->\s*", re.S)


def source_kind(source: str | Path) -> str:
    """"osm" or "net" by the file name, or InputError."""
    name = Path(source).name.lower()
    if name.endswith(OSM_SUFFIXES):
        return "osm"
    if name.endswith(NET_SUFFIXES):
        return "net"
    raise InputError(str(source), "", "not a SUMO net or an OpenStreetMap file",
                     f"pass a file ending in {', '.join(NET_SUFFIXES + OSM_SUFFIXES)}")


def netconvert_osm_command(binary: str, source: Path, output: Path) -> list[str]:
    return [binary, "--osm-files", str(source), "--output-file", str(output), *OSM_OPTIONS]


def convert_osm(source: str | Path) -> bytes:
    """The SUMO net of an OSM extract, as bytes without netconvert's dated header, or InputError
    naming the file when netconvert rejects it."""
    source = Path(source)
    if not source.is_file():
        raise InputError(str(source), "", "the OpenStreetMap file does not exist",
                         "pass an existing .osm file")
    binary = find_binary("netconvert")
    environment = dict(os.environ)
    import sumo

    # netconvert finds its OSM type maps under SUMO_HOME (the wheel's folder unless set).
    environment.setdefault("SUMO_HOME", str(sumo.SUMO_HOME))
    with tempfile.TemporaryDirectory(prefix="trustroute-osm-") as work:
        output = Path(work) / "osm.net.xml"
        result = subprocess.run(netconvert_osm_command(binary, source.resolve(), output), capture_output=True,
                                text=True, check=False, env=environment)
        if result.returncode != 0 or not output.is_file():
            errors = [line.removeprefix("Error: ").strip()
                      for line in (result.stderr or result.stdout).splitlines() if line.startswith("Error")]
            raise InputError(str(source), "", "netconvert rejected the OpenStreetMap file: "
                             + ("; ".join(errors[:2]) if errors else f"exit {result.returncode}"),
                             "pass an OSM XML extract (e.g. exported from openstreetmap.org) that "
                             "contains streets")
        return GENERATED_HEADER.sub(b"", output.read_bytes(), count=1)
