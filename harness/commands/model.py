"""`trustroute model`: print a summary of the trust POMDP for a town and driver model."""

from __future__ import annotations

import json

import click

from trustroute.app.towns import model_summary
from trustroute.harness.commands.inputs import driver_option, town_only_option
from trustroute.harness.commands.output import json_option, with_paths


@click.command("model")
@town_only_option
@driver_option
@json_option
def model(town_path: str | None, driver_path: str | None, as_json: bool) -> None:
    """Summarise the trust POMDP of a town and a driver model."""
    summary = model_summary(town_path, driver_path)
    if as_json:
        click.echo(json.dumps(with_paths(summary, {})))
        return
    one_way = summary["one_way_roads"]
    roads = (f"{summary['roads']} two-way roads" if one_way == 0 else
             f"{summary['roads'] - one_way} two-way and {one_way} one-way roads")
    click.echo(f"town {summary['town']} ({summary['town_hash']}): {summary['junctions']} junctions,"
               f" {roads}, {summary['states']} states (directed roads)")
    click.echo("incidents per directed road: " + ", ".join(
        f"{k} {v}" for k, v in summary["incidents_per_type"].items()))
    click.echo(f"driver model {summary['driver_model']} ({summary['driver_hash']}): trust levels "
               f"{summary['trust_levels'][0]}..{summary['trust_levels'][-1]}, performance-dependent "
               f"dynamics: {summary['performance_dependent']}")
    for kind, row in summary["takeover_probability"].items():
        click.echo(f"  P(takeover | trust, {kind:10s}) = {row}")
