"""`trustroute spec check SPEC`: parse a spec, translate it to its DFA and lint it.

Prints the DFA size, how many junctions apart the waypoint sets lie (the state atoms in the order
the formula names them, from the start road) and the warnings of policies/logic/lint.py (against
the default town unless --town is given); --json prints one object; --dot writes the DFA as
Graphviz dot.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from trustroute.core.errors import InputError
from trustroute.harness.commands.output import json_option, with_paths


def spec_report(spec_path: str, town_path: str | None, population_path: str | None = None,
                driver_path: str | None = None) -> tuple[dict, str]:
    """(the JSON-ready summary of a spec check, the DFA as dot text). The spec is loaded as every
    command loads it: against the town and the driver model (`driver_path`, default the packaged
    model) or, with population_path, the driver population (type-belief atoms, the threshold check
    on its type-aware filter; docs/driver_types.md)."""
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.participants.driver_population import load_driver_population
    from trustroute.policies.logic.dfa import DFATooLarge, dfa_from_formula
    from trustroute.policies.logic.lint import lint
    from trustroute.policies.logic.spec import load_spec

    if population_path is not None and driver_path is not None:
        raise click.UsageError("give --driver or --population, not both")
    town = load_town(town_path)
    if population_path is None:
        population, driver = None, load_driver_model(driver_path)
        spec = load_spec(spec_path, town, driver.n_trust, driver.source_path)
    else:
        population = load_driver_population(population_path)
        spec = load_spec(spec_path, town, population.types[0].model.n_trust, population_path)
    started = time.perf_counter()
    try:
        dfa = dfa_from_formula(spec.formula, spec.formula_atoms)
    except DFATooLarge as exc:
        raise InputError(spec.source_path, "formula", f"the formula is too large to translate ({exc})",
                         "split the task or simplify the formula") from None
    except RecursionError:
        raise InputError(spec.source_path, "formula", "the formula is nested too deeply to translate",
                         "simplify the formula") from None
    seconds = time.perf_counter() - started
    if population_path is not None and population is not None:
        from trustroute.policies.belief.driver_types import lift_population, lift_spec

        lifted = lift_spec(spec, population, population_path)   # a type it lacks: one line, exit 2
        warnings = lint(lifted, town, dfa, lift_population(population))
    else:
        warnings = lint(spec, town, dfa, driver)
    summary = {
        "name": spec.name,
        "file": spec.source_path,
        "start": spec.start,
        "formula": spec.formula_text,
        "content_hash": spec.content_hash,
        "town": town.source_path,
        "atoms": list(dfa.atoms),
        "state_atoms": sorted(a for a in spec.state_atoms if a in dfa.atoms),
        "belief_atoms": sorted(a for a in spec.belief_atoms if a in dfa.atoms),
        "trust_atoms": sorted(a for a in spec.trust_atoms if a in dfa.atoms),
        "type_belief_atoms": sorted(a for a in spec.type_atoms if a in dfa.atoms),
        "dfa_states": dfa.n_states,
        "accepting_states": int(dfa.accepting.sum()),
        "rejecting_states": int(dfa.rejecting.sum()),
        "translation_seconds": seconds,
        "warnings": [{"code": w.code, "message": w.message, "atom": w.atom} for w in warnings],
        "waypoints": waypoint_summary(spec, town),
    }
    return summary, dfa.to_dot(spec.name)


def waypoint_summary(spec, town) -> list[dict]:
    """The state atoms in the order the formula first names them, with their road counts and the
    fewest junctions from the previous one (the start road first; networks/road_lookup.py)."""
    from trustroute.networks.road_lookup import waypoint_legs

    waypoints = [(atom, spec.state_atoms[atom]) for atom in spec.formula_atoms if atom in spec.state_atoms]
    legs = waypoint_legs(town, spec.start, waypoints)
    return [{**leg.to_dict(), "roads": len(roads)} for leg, (_, roads) in zip(legs, waypoints, strict=True)]


def waypoint_line(start: str, waypoints: list[dict]) -> str:
    """`start E-A -> v1 (3 roads): 2 junctions -> ...`."""
    parts = [f"start {start}"]
    for leg in waypoints:
        apart = "unreachable" if leg["junctions"] is None else (
            f"{leg['junctions']} junction{'' if leg['junctions'] == 1 else 's'}")
        parts.append(f"{leg['to']} ({leg['roads']} roads): {apart}")
    return "waypoints, fewest junctions from the previous: " + " -> ".join(parts)


@click.group("spec")
def spec() -> None:
    """Check scLDTL spec files."""


@spec.command("check")
@click.argument("spec_path", metavar="SPEC")
@click.option("--town", "town_path", type=click.Path(), default=None, help="Town file (default town).")
@json_option
@click.option("--dot", "dot_path", type=click.Path(), default=None,
              help="FILE to write the DFA into, as Graphviz dot.")
@click.option("--driver", "driver_path", type=click.Path(), default=None,
              help="Driver model FILE the belief atoms' coefficients are checked against (default model).")
@click.option("--population", "population_path", type=click.Path(), default=None,
              help="Driver-population FILE to check type-belief atoms against (docs/driver_types.md).")
def check(spec_path: str, town_path: str | None, as_json: bool, dot_path: str | None,
          driver_path: str | None, population_path: str | None) -> None:
    """Parse SPEC, print its DFA size and the linter's warnings."""
    from trustroute.core.output_files import atomic_write_text, check_output_file

    if dot_path is not None:
        check_output_file(dot_path, "--dot", "dot file")
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
