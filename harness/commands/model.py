"""`trustroute model`: print a summary of the trust POMDP for a town and driver model."""

from __future__ import annotations

import json

import click
import numpy as np

from trustroute.harness.commands.output import json_option
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.policies.model.trust_pomdp import build_pomdp


def model_summary(town_path: str | None, driver_path: str | None) -> dict:
    town = load_town(town_path)
    driver = load_driver_model(driver_path)
    pomdp = build_pomdp(town, driver)
    incidents = {}
    for kind in driver.incident_types:
        incidents[kind] = sum(1 for v in town.incidents.values() if v == kind)
    return {
        "town": town.source_path,
        "town_hash": town.content_hash[:12],
        "junctions": len(town.junctions),
        "roads": len(town.roads),
        "states": pomdp.n_states,
        "incidents_per_type": incidents,
        "trust_levels": list(driver.trust_levels),
        "driver_model": driver.source_path,
        "driver_hash": driver.content_hash[:12],
        "performance_dependent": driver.depends_on_performance,
        "initial_belief": np.round(driver.initial_belief, 4).tolist(),
        "takeover_probability": {
            kind: np.round(driver.takeover_probability[i], 3).tolist()
            for i, kind in enumerate(driver.incident_types)
        },
    }


@click.command("model")
@click.option("--town", "town_path", type=click.Path(), default=None, help="Town file (default town).")
@click.option("--driver", "driver_path", type=click.Path(), default=None,
              help="Driver model file (default model).")
@json_option
def model(town_path: str | None, driver_path: str | None, as_json: bool) -> None:
    """Summarise the trust POMDP of a town and a driver model."""
    summary = model_summary(town_path, driver_path)
    if as_json:
        click.echo(json.dumps(summary))
        return
    click.echo(f"town {summary['town']} ({summary['town_hash']}): {summary['junctions']} junctions,"
               f" {summary['roads']} two-way roads, {summary['states']} states (directed roads)")
    click.echo("incidents per directed road: " + ", ".join(
        f"{k} {v}" for k, v in summary["incidents_per_type"].items()))
    click.echo(f"driver model {summary['driver_model']} ({summary['driver_hash']}): trust levels "
               f"{summary['trust_levels'][0]}..{summary['trust_levels'][-1]}, performance-dependent "
               f"dynamics: {summary['performance_dependent']}")
    for kind, row in summary["takeover_probability"].items():
        click.echo(f"  P(takeover | trust, {kind:10s}) = {row}")
