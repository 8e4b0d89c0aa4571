"""`trustroute town import SOURCE --out town.json`: a SUMO net or an OpenStreetMap extract as a town;
`trustroute town roads TOWN [--near X Y] [--street NAME]`: a town's roads near a point or on a street.

import prints the town file written and its size; one line on stderr says what the import left out
(--quiet and --json keep it off). The work is networks/town_import.py's and
networks/road_lookup.py's.
"""

from __future__ import annotations

from pathlib import Path

import click

from trustroute.core import ranges
from trustroute.harness.commands.options import Checked, UsageFix
from trustroute.harness.commands.output import emit, json_option, quiet_option, with_paths


@click.group("town")
def town() -> None:
    """Import real road networks as towns, and find their roads."""


@town.command("import")
@click.argument("source", type=click.Path())
@click.option("--out", "out", type=click.Path(), required=True, help="The town file to write (JSON).")
@click.option("--incidents", "incidents_path", type=click.Path(), default=None,
              help="JSON FILE of incidents by road \"U-V\" or SUMO edge id (others: none).")
@click.option("--incident-seed", type=Checked(ranges.INCIDENT_SEED), default=None,
              help="Draw the incidents by the seeded rule of docs/formats/town.md.")
@click.option("--net-out", type=click.Path(), default=None,
              help="Where an OSM import writes its SUMO net (default: beside --out, NAME.net.xml).")
@quiet_option
@json_option
def import_command(source: str, out: str, incidents_path: str | None, incident_seed: int | None,
                   net_out: str | None, quiet: bool, as_json: bool) -> None:
    """Import SOURCE (.net.xml, .net.xml.gz or .osm) as a town: its decision junctions, its roads
    with their shapes and lengths, one-way streets kept one-way."""
    from trustroute.app.towns import import_town_file
    from trustroute.core.output_files import check_output_file

    if incidents_path is not None and incident_seed is not None:
        raise UsageFix("--incidents and --incident-seed were both given",
                       "pass --incidents or --incident-seed, not both")
    reads = {"SOURCE": source, "--incidents": incidents_path}
    check_output_file(out, "--out", "town file", reads)
    if net_out is not None:
        check_output_file(net_out, "--net-out", "SUMO net", reads)
    result = import_town_file(source, out, incidents_path, incident_seed, net_out)
    if not (quiet or as_json):
        click.echo(f"{Path(source).name}: {result.graph.summary()}", err=True)
    emit(as_json, with_paths(result.to_dict(), {"town": result.town_path, "net": result.net_path}),
         [str(result.town_path), result.summary()])


@town.command("roads")
@click.argument("town_path", metavar="TOWN", type=click.Path())
@click.option("--near", type=click.Tuple([Checked(ranges.COORDINATE)] * 2), default=None, metavar="X Y",
              help="List the roads nearest this point (metres, the town's coordinates) first.")
@click.option("--street", default=None, metavar="NAME", help="Only the roads on this street (case ignored).")
@click.option("--limit", type=Checked(ranges.ROAD_LIMIT), default=None,
              help="At most N roads (default: 10 with --near, else all).")
@json_option
def roads_command(town_path: str, near: tuple[float, float] | None, street: str | None, limit: int | None,
                  as_json: bool) -> None:
    """Print TOWN's directed roads with length, street and incident: those near a point, or on a
    street. Spec files can name waypoint sets by junction or street (docs/formats/spec.md)."""
    from trustroute.app.towns import town_roads

    source, rows = town_roads(town_path, near, street, limit)
    lines = [f"{row.road}  {row.length:.1f} m  {row.incident}  {row.street or '(no street name)'}"
             + ("" if row.distance is None else f"  {row.distance:.1f} m away") for row in rows]
    emit(as_json, {"town": source, "roads": [row.to_dict() for row in rows]}, lines)
