"""SUMO-native files of an episode (`trustroute run --sumo-files DIR`), so sumo-gui and netedit open
it without trustroute:

    DIR/net.net.xml       the town's net (a copy; net.net.xml.gz for a gzipped imported net)
    DIR/routes.rou.xml    SUMO's vehroute output of the episode: the ego's route as driven (last
                          route), the incident vehicles with their depart times, persons
    DIR/fcd.xml           SUMO's floating car data of the episode as it ran (every vehicle and person,
                          every step), written by SUMO itself during the run
    DIR/episode.sumocfg   net + routes, the episode's seed and step length; when re-run it writes
                          DIR/fcd.replay.xml (so fcd.xml is kept)

Re-running episode.sumocfg replays the vehicles' routes with SUMO's own driver model: takeovers,
stops at incidents and the policy's decisions are TraCI actions of trustroute and are not in the
route file, so only fcd.xml is the episode exactly.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import TYPE_CHECKING
from xml.sax.saxutils import quoteattr

from trustroute.core.errors import InputError
from trustroute.harness.simulation.sumo_start import Sumo, SumoConfig

if TYPE_CHECKING:
    from trustroute.harness.simulation.incidents.base import EgoState

CONFIG_FILE = "episode.sumocfg"


def prepare_directory(directory: Path) -> Path:
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(str(directory), "", f"cannot create the directory ({exc.strerror})",
                         "pass a writable directory with --sumo-files") from None
    return directory


def write_episode_files(directory: Path, types: dict[str, dict[str, str]], net_path: Path, seed: int,
                        config: SumoConfig) -> dict[str, Path]:
    """After the episode: finish SUMO's route output, copy the net beside it and write the .sumocfg
    that opens them; every file in `directory`, by name (those SUMO wrote during the run too)."""
    directory = Path(directory)
    routes = finish_route_file(directory, types)
    sumocfg = write_sumocfg(directory, net_path, seed, config)
    return {"sumocfg": sumocfg, "net": directory / net_file_name(net_path), "routes": routes,
            "fcd": directory / "fcd.xml"}


def net_file_name(net_path: Path) -> str:
    """The name of the net's copy: gzipped stays gzipped (SUMO reads either)."""
    return "net.net.xml.gz" if str(net_path).endswith(".gz") else "net.net.xml"


def write_sumocfg(directory: Path, net_path: Path, seed: int, config: SumoConfig) -> Path:
    """Copy the net beside the outputs and write the .sumocfg that opens them."""
    directory = Path(directory)
    net_file = net_file_name(net_path)
    shutil.copyfile(net_path, directory / net_file)
    text = f"""<?xml version="1.0" encoding="UTF-8"?>
<!-- One trustroute episode. Open with: sumo-gui -c {CONFIG_FILE} (fcd.xml is the episode as run). -->
<configuration>
    <input>
        <net-file value="{net_file}"/>
        <route-files value="routes.rou.xml"/>
    </input>
    <time>
        <step-length value={quoteattr(f"{config.step_length:g}")}/>
    </time>
    <random_number>
        <seed value="{int(seed)}"/>
    </random_number>
    <processing>
        <time-to-teleport value="-1"/>
        <pedestrian.model value="striping"/>
        <pedestrian.striping.dawdling value="0"/>
        <collision.action value="warn"/>
    </processing>
    <output>
        <fcd-output value="fcd.replay.xml"/>
    </output>
</configuration>
"""
    path = directory / CONFIG_FILE
    path.write_text(text)
    return path


class VehicleTypeCollector:
    """An episode observer that notes every vehicle type trustroute defines through TraCI (the ego's,
    the incidents'), so the route file can define them: SUMO's vehroute output only names them."""

    def __init__(self) -> None:
        self.types: dict[str, dict[str, str]] = {}

    def __call__(self, sumo: Sumo, ego: EgoState, mode: str, road: str) -> None:
        del ego, mode, road
        for type_id in sumo.vehicletype.getIDList():
            if type_id in self.types or type_id.startswith("DEFAULT_") or "@" in type_id:
                continue
            vt = sumo.vehicletype
            r, g, b, a = vt.getColor(type_id)
            self.types[type_id] = {
                "vClass": vt.getVehicleClass(type_id),
                "guiShape": vt.getShapeClass(type_id),
                "length": f"{vt.getLength(type_id):g}",
                "width": f"{vt.getWidth(type_id):g}",
                "minGap": f"{vt.getMinGap(type_id):g}",
                "maxSpeed": f"{vt.getMaxSpeed(type_id):g}",
                "accel": f"{vt.getAccel(type_id):g}",
                "decel": f"{vt.getDecel(type_id):g}",
                "sigma": f"{vt.getImperfection(type_id):g}",
                "tau": f"{vt.getTau(type_id):g}",
                "speedDev": f"{vt.getSpeedDeviation(type_id):g}",
                "color": f"{r},{g},{b},{a}",
            }


def finish_route_file(directory: Path, types: dict[str, dict[str, str]]) -> Path:
    """Make SUMO's vehroute output loadable on its own: vehicle-specific type copies ("T@vehicle")
    become their base type T, every trustroute type gets a <vType> definition, departures are sorted."""
    import xml.etree.ElementTree as ET

    path = Path(directory) / "routes.rou.xml"
    tree = ET.parse(path)
    root = tree.getroot()
    movers = [element for element in root if "depart" in element.attrib]
    for element in movers:
        if "type" in element.attrib:
            element.set("type", element.attrib["type"].split("@")[0])
        root.remove(element)
    # SUMO loads a route file in departure order (unfinished vehicles, like the ego, come last).
    root.extend(sorted(movers, key=lambda e: float(e.attrib["depart"])))
    for position, (type_id, attributes) in enumerate(sorted(types.items())):
        root.insert(position, ET.Element("vType", {"id": type_id, **attributes}))
    ET.indent(tree, "    ")
    tree.write(path, encoding="UTF-8", xml_declaration=True)
    return path
