"""`trustroute spec check SPEC`: parse a spec, translate it to its DFA and lint it.

Prints the DFA size, how many junctions apart the waypoint sets lie (the state atoms in the order
the formula names them, from the start road) and the warnings of policies/logic/lint.py (against
the default town unless --town is given); --json prints one object; --dot writes the DFA as
Graphviz dot.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from trustroute.app.spec_check import spec_report
from trustroute.core.wording import counted
from trustroute.harness.commands.inputs import POPULATION_GIVEN, spec_argument, town_option
from trustroute.harness.commands.output import json_option, with_paths


def waypoint_line(start: str, waypoints: list[dict]) -> str:
    """`start E-A -> v1 (3 roads): 2 junctions -> ...`."""
    parts = [f"start {start}"]
    for leg in waypoints:
        apart = "unreachable" if leg["junctions"] is None else counted(leg["junctions"], "junction")
        parts.append(f"{leg['to']} ({counted(leg['roads'], 'road')}): {apart}")
    return "waypoints, fewest junctions from the previous: " + " -> ".join(parts)


@click.group("spec")
def spec() -> None:
    """Check scLDTL spec files."""


@spec.command("check")
@spec_argument()
@town_option
@json_option
@click.option("--dot", "dot_path", type=click.Path(), default=None,
              help="FILE to write the DFA into, as Graphviz dot.")
@click.option("--driver", "driver_path", type=click.Path(), default=None,
              help="Driver model FILE the belief atoms' coefficients are checked against (default model).")
@click.option("--population", "population_path", type=click.Path(), default=None,
              help=f"{POPULATION_GIVEN} to check type-belief atoms against (docs/driver_types.md).")
def check(spec_path: str, town_path: str | None, as_json: bool, dot_path: str | None,
          driver_path: str | None, population_path: str | None) -> None:
    """Parse SPEC, print its DFA size and the linter's warnings."""
    from trustroute.core.output_files import atomic_write_text, check_output_file

    if dot_path is not None:
        check_output_file(dot_path, "--dot", "dot file", {"SPEC": spec_path, "--town": town_path,
                                                          "--driver": driver_path,
                                                          "--population": population_path}, suffix=".dot")
    summary, dot = spec_report(spec_path, town_path, population_path, driver_path)
    if dot_path is not None:
        atomic_write_text(Path(dot_path), dot, "dot file", "pass a writable path to --dot")
    if as_json:
        click.echo(json.dumps(with_paths(summary, {"dot": dot_path})))
        return
    click.echo(f"{summary['name']} ({summary['file']}): start {summary['start']}, "
               f"formula {summary['formula']}")
    click.echo(f"DFA: {summary['dfa_states']} states ({summary['accepting_states']} accepting, "
               f"{summary['rejecting_states']} rejecting) over {len(summary['atoms'])} atoms "
               f"({', '.join(summary['atoms'])}), "
               f"translated in {summary['translation_seconds'] * 1e3:.1f} ms")
    if summary["waypoints"]:
        click.echo(waypoint_line(summary["start"], summary["waypoints"]))
    if not summary["warnings"]:
        click.echo("no warnings")
    for warning in summary["warnings"]:
        click.echo(f"warning [{warning['code']}]: {warning['message']}")
    if dot_path is not None:
        click.echo(f"wrote {dot_path}")
