"""Screenshots of an obstacle overtake with an oncoming truck, in sumo-gui (docs/scenes.md).

Run under a virtual display:
    xvfb-run -s "-screen 0 1280x960x24" .venv/bin/python docs/img/make_screenshots.py
It builds the default town's net, starts sumo-gui through TraCI with the harness's own command
line, and places the scene with the harness's own incident code (obstacle.inject with an
oncoming truck timed to meet the ego), then saves two views: the ego waiting behind the parked
obstacle while the truck comes towards it, and the ego passing the obstacle in the oncoming lane.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import sumolib
import traci

from trustroute.harness.simulation import incidents
from trustroute.harness.simulation.driving_style import AUTOPILOT, apply_style
from trustroute.harness.simulation.incidents import Scene, obstacle
from trustroute.harness.simulation.sumo_start import SumoConfig, sumo_command
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import load_town

OUT = Path(__file__).resolve().parent


def main() -> int:
    net = build_net(load_town()).path
    command = [sumolib.checkBinary("sumo-gui"), *sumo_command(net, 3, SumoConfig())[1:],
               "--window-size", "1200,900", "--start", "true", "--quit-on-end", "true",
               "--gui-settings-file", str(OUT / "gui-settings.xml")]
    (OUT / "gui-settings.xml").write_text(
        '<viewsettings><scheme name="real world"/><delay value="0"/></viewsettings>\n')
    traci.start(command)
    try:
        traci.vehicletype.copy("DEFAULT_VEHTYPE", "ego")
        traci.vehicletype.setImperfection("ego", 0.0)
        incidents.define_types(traci)
        traci.route.add("ego_route", ["B-C", "C-J", "J-K"])
        # 70 m before C (Town01's B-C is shorter: from its start)
        depart = max(0.0, traci.lane.getLength("B-C_1") - 70)
        traci.vehicle.add("ego", "ego_route", typeID="ego", departPos=f"{depart:.2f}", departSpeed="max")
        apply_style(traci, "ego", AUTOPILOT)
        traci.simulationStep()
        scene = Scene(road="C-J", reverse_road="J-C", road_length=traci.lane.getLength("C-J_1"),
                      prefix="shot", ego_id="ego", time=traci.simulation.getTime(), ego_distance=78.0,
                      rng=np.random.default_rng(0),
                      overrides={"oncoming": True, "oncoming_offset": 1.0, "bicycle": False,
                                 "position_fraction": 0.4, "unseen": False})
        incident = obstacle.inject(traci, scene)
        view = "View #0"
        shots = {"waiting": None, "overtaking": None}
        for _ in range(400):
            traci.simulationStep()
            if "ego" not in traci.vehicle.getIDList():
                break   # arrived before both views were taken: the scene did not play as staged
            lane, speed = traci.vehicle.getLaneID("ego"), traci.vehicle.getSpeed("ego")
            x, y = traci.vehicle.getPosition("ego")
            if shots["waiting"] is None and lane == "C-J_1" and speed < 2.0:
                shots["waiting"] = OUT / "obstacle_wait_for_oncoming_truck.png"
            elif shots["overtaking"] is None and lane == "J-C_1" and shots["waiting"] is not None:
                beside = traci.lane.getLength("J-C_1") - incident.position_on_road
                if traci.vehicle.getLanePosition("ego") < beside:
                    shots["overtaking"] = OUT / "obstacle_overtake_in_oncoming_lane.png"
            for name, path in shots.items():
                if path is not None and not path.exists() and not str(path).endswith(".done"):
                    # centred between the ego and the truck, so that both are in view (about 80 m
                    # across at this zoom on Town01's net)
                    truck = incident.oncoming.vehicle_id
                    present = truck in traci.vehicle.getIDList()
                    tx, ty = traci.vehicle.getPosition(truck) if present else (x, y)
                    traci.gui.setOffset(view, (x + tx) / 2, (y + ty) / 2)
                    traci.gui.setZoom(view, 700)
                    traci.gui.screenshot(view, str(path))
                    traci.simulationStep()   # the screenshot is written at the end of the next step
                    shots[name] = Path(str(path) + ".done")
            if all(p is not None and str(p).endswith(".done") for p in shots.values()):
                break
    finally:
        traci.close()
    return 0 if (OUT / "obstacle_overtake_in_oncoming_lane.png").exists() else 1


if __name__ == "__main__":
    sys.exit(main())
