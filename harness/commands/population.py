"""`trustroute population`: driver-population files (docs/driver_type_studies.md).

sample   K driver types sampled around a nominal driver model with `[population]` settings
         (participants/sampled_types.py), written as a driver-population file
show     the types of a driver-population file, their weights and what sets them apart
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from trustroute.app.populations import NOMINAL, sample_population
from trustroute.core import ranges
from trustroute.harness.commands.options import SEED, Checked
from trustroute.harness.commands.output import emit, json_option, with_paths


@click.group("population")
def population() -> None:
    """Sample, fit (`trustroute fit --types`) and inspect driver populations."""


@population.command("sample")
@click.option("--types", "n_types", type=Checked(ranges.SAMPLED_TYPES), required=True,
              help="Number of types K.")
@click.option("--seed", type=SEED, required=True, help="Seed of the draws.")
@click.option("--out", type=click.Path(), required=True, help="Driver-population FILE to write.")
@click.option("--driver", "driver_path", type=click.Path(), default=None,
              help="Nominal driver model file (default: the packaged model).")
@click.option("--config", "config_path", type=click.Path(), default=None,
              help="TOML file whose [population] table gives the spread (e.g. a study config).")
@click.option("--concentration", type=Checked(ranges.CONCENTRATION), default=None,
              help="Dirichlet concentration of the rows around the nominal ones (overrides --config; "
                   f"default: --config's, else {NOMINAL.concentration:g}, the nominal rows).")
@click.option("--takeover-spread", "spread", type=Checked(ranges.TAKEOVER_SPREAD), default=None,
              help="sd of each type's logit shift of its takeover probabilities (overrides --config; "
                   f"default: --config's, else {NOMINAL.takeover_spread:g}).")
@json_option
def sample(n_types: int, seed: int, out: str, driver_path: str | None, config_path: str | None,
           concentration: float | None, spread: float | None, as_json: bool) -> None:
    """Sample K driver types around a nominal model; equal weights.

    Needs a spread: a finite --concentration, a --takeover-spread above 0, or a --config whose
    [population] table gives one. The defaults give every type the nominal model, which is refused.
    """
    from trustroute.core.output_files import check_output_file

    check_output_file(out, "--out", "driver-population file",
                      {"--driver": driver_path, "--config": config_path})
    result, path = sample_population(n_types, seed, Path(out), driver_path, config_path, concentration,
                                     spread)
    summary = {**population_summary(result), "source": str(path)}
    emit(as_json, with_paths(summary, {"population": path}),
         [*summary_lines(summary), f"driver population written to {path}"])


@population.command("show")
@click.argument("path", metavar="FILE", type=click.Path())
@json_option
def show(path: str, as_json: bool) -> None:
    """Print the types of a driver-population file and their weights."""
    from trustroute.app.inputs import population_of

    summary = population_summary(population_of(path, given="FILE"))
    emit(as_json, summary, summary_lines(summary))


def population_summary(pop) -> dict:
    """Per type: weight, mean initial trust, mean takeover probability per incident, and the
    expected trust change per road without a takeover (averaged over trust levels)."""
    types = []
    for t in pop.types:
        model = t.model
        levels = np.asarray(model.trust_levels, dtype=float)
        change = model.trust_transition[:, 0, 0] @ levels - levels  # [I, k]: standstill, AV success
        types.append({
            "name": t.name,
            "weight": float(t.weight),
            "initial_mean_trust": float(model.initial_belief @ levels),
            "takeover_probability_mean": {inc: float(model.takeover_probability[i].mean())
                                          for i, inc in enumerate(model.incident_types)},
            "expected_trust_change": {inc: float(change[i].mean())
                                      for i, inc in enumerate(model.incident_types)},
            "model_hash": model.content_hash[:12],
        })
    return {"source": str(pop.source_path), "provenance": pop.provenance, "types": types,
            "content_hash": pop.content_hash}


def summary_lines(summary: dict) -> list[str]:
    lines = [f"{len(summary['types'])} driver types ({summary['source'] or 'not written yet'}): "
             f"{summary['provenance']}"]
    for t in summary["types"]:
        takeover = ", ".join(f"{k} {v:.2f}" for k, v in t["takeover_probability_mean"].items())
        change = ", ".join(f"{k} {v:+.2f}" for k, v in t["expected_trust_change"].items())
        lines.append(f"  {t['name']}: weight {t['weight']:.3f}, initial mean trust "
                     f"{t['initial_mean_trust']:.2f}; mean takeover {takeover}; trust change/road {change}")
    return lines
