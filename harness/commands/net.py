"""`trustroute net build`: build (or take from the cache) the SUMO network of a town."""

from __future__ import annotations

import json

import click

from trustroute.harness.commands.inputs import town_only_option
from trustroute.harness.commands.output import json_option, with_paths


@click.group("net")
def net() -> None:
    """Build and inspect the SUMO network of a town."""


@net.command("build")
@town_only_option
@click.option("--out", "out_dir", type=click.Path(), default=None,
              help="DIRECTORY of the net cache (default: $XDG_CACHE_HOME/trustroute/nets, "
              "XDG_CACHE_HOME defaulting to ~/.cache).")
@json_option
def build(town_path: str | None, out_dir: str | None, as_json: bool) -> None:
    """Build the town's .net.xml with netconvert, cached by the town's content hash (a town
    imported from a net drives that net: it is printed, nothing is built)."""
    from trustroute.app.towns import build_town_net
    from trustroute.core.output_files import check_output_dir

    if out_dir is not None:
        check_output_dir(out_dir, "--out", "net cache")
    result = build_town_net(town_path, out_dir)
    if as_json:
        click.echo(json.dumps(with_paths(result.to_dict(), {"net": result.path})))
        return
    click.echo(str(result.path))
    click.echo(f"{result.edges} edges, {result.junctions} junctions, {result.connections} connections, "
               f"{result.crossings} crossings; {'cached' if result.cached else 'built'} in "
               f"{result.seconds:.3f} s")
