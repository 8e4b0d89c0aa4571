"""`trustroute fit`: estimate a driver model (trust dynamics, takeover model) from a study's logs,
with an optional bootstrap and posterior-predictive check; with --types, a mixture of driver types
(a driver-population file, docs/driver_type_studies.md).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import click

from trustroute.core import defaults, ranges
from trustroute.core.progress import bar_disable
from trustroute.core.wording import counted
from trustroute.harness.commands.option_groups import option, takes
from trustroute.harness.commands.options import Checked, UsageFix, range_metavar
from trustroute.harness.commands.output import json_flag, quiet_flag, study_warnings, with_paths

CHECK_REPLICATES = 50  # simulated drivers per real episode in `fit --check`
CHECK_EPISODES = 20_000  # model-engine episodes per spec, condition and driver model in `fit --check`


@dataclass(frozen=True)
class FitOptions:
    """`trustroute fit`'s options, in the order --help lists them."""

    out: str = option("--out", type=click.Path(), default="driver.json", show_default=True,
                      help="Driver model FILE to write.")
    method: str = option(
        "--method", type=click.Choice(defaults.FIT_METHODS), default=defaults.FIT_METHOD, show_default=True,
        help="counts: reports are exact trust; em: reports are noisy (EM over hidden trust); "
        "auto: counts when the study's report accuracy is 1 and trust is reported every road.")
    iterations: int = option("--iterations", type=Checked(ranges.ITERATIONS), default=defaults.FIT_ITERATIONS,
                             show_default=True, help="EM iterations at most.")
    bootstrap: int = option("--bootstrap", type=Checked(ranges.BOOTSTRAP), default=0, show_default=True,
                            help="Resamples of participants for percentile intervals (0: none).")
    seed: int = option("--seed", type=Checked(ranges.DRAW_SEED), default=0, show_default=True,
                       help="Seed of the bootstrap and the check.")
    check: bool = option(
        "--check", is_flag=True,
        help="Posterior-predictive check: simulate the packaged and the fitted model on the study's "
        "roads and compare with its logs (writes <out>.check.json and <out>.check.png).")
    types: str | None = option("--types", default=None, metavar=f"{range_metavar(ranges.TYPES)}|auto",
                               help="Fit a mixture of this many driver types (or choose how many by BIC "
                               "with 'auto') and write a driver-population file.")
    max_types: int = option("--max-types", type=Checked(ranges.MAX_TYPES), default=defaults.FIT_MAX_TYPES,
                            show_default=True, help="With --types auto: the largest number of types tried.")
    restarts: int = option("--restarts", type=Checked(ranges.RESTARTS), default=defaults.FIT_RESTARTS,
                           show_default=True, help="With --types: seeded EM restarts per number of types.")
    shared_dynamics: bool = option(
        "--shared-dynamics", is_flag=True,
        help="With --types: the types share the trust-transition rows and differ in initial "
        "trust and takeover (and failure) probabilities.")
    as_json: bool = json_flag()
    quiet: bool = quiet_flag()


@click.command("fit")
@click.argument("study_dir", metavar="DIR", type=click.Path())
@takes(options=FitOptions)
def fit(study_dir: str, options: FitOptions) -> None:
    """Estimate trust dynamics and the takeover model from a study's logs; write a driver model."""
    from trustroute.analysis.fitting.driver_model import bootstrap_fit, fit_study
    from trustroute.core.output_files import atomic_write_text, check_output_file

    out, method, iterations, bootstrap, seed = (options.out, options.method, options.iterations,
                                                options.bootstrap, options.seed)
    check, as_json, quiet = options.check, options.as_json, options.quiet
    mixture_only = [flag for flag, given in (
        ("--max-types", options.max_types != defaults.FIT_MAX_TYPES),
        ("--restarts", options.restarts != defaults.FIT_RESTARTS),
        ("--shared-dynamics", options.shared_dynamics)) if given]
    if options.types is None and mixture_only:   # else they would change nothing without a word
        raise UsageFix(f"{mixture_only[0]} sets the fit of driver types, and --types is not given",
                       f"add --types K or --types auto, or drop {mixture_only[0]}")
    if options.types is not None:
        if check or method == "counts":
            raise UsageFix("--types fits by EM; it takes neither --check nor --method counts",
                           "drop --check and --method counts, or drop --types")
        fixed = _type_count(options.types)
        check_output_file(out, "--out", "driver-population file", studies={"DIR": study_dir})
        fit_types(Path(study_dir), Path(out), options, fixed, study_warnings(Path(study_dir)))
        return
    check_output_file(out, "--out", "driver model file", studies={"DIR": study_dir})
    warnings = study_warnings(Path(study_dir))
    result = fit_study(Path(study_dir), method=method, iterations=iterations,
                       progress=not (quiet or as_json))
    path = result.write(Path(out))
    payload = {**result.summary(), "warnings": warnings}
    paths: dict[str, Path] = {"driver_model": path}
    if bootstrap:
        import numpy as np
        from tqdm import tqdm

        from trustroute.analysis.study_directory import load_study, study_inputs

        manifest, episodes, roads = load_study(Path(study_dir))
        _, template, _ = study_inputs(manifest, Path(study_dir))
        with tqdm(total=bootstrap, desc="bootstrap", disable=bar_disable(not (quiet or as_json))) as bar:
            payload["bootstrap"] = bootstrap_fit(
                roads,
                episodes,
                template,
                result.method,
                iterations,
                bootstrap,
                np.random.default_rng(seed),
                progress=bar.update,
            )
        paths["bootstrap"] = atomic_write_text(Path(path).with_suffix(".bootstrap.json"),
                                               json.dumps(payload["bootstrap"], indent=1),
                                               "bootstrap intervals", "pass a writable path with --out")
    if check:
        import numpy as np

        from trustroute.analysis.fitting.posterior_check import plot_check, write_check
        from trustroute.analysis.study_directory import load_study, study_inputs
        from trustroute.app.populations import REPORT_ACCURACY
        from trustroute.app.runs import aware_vs_free, posterior_check

        manifest, _, roads = load_study(Path(study_dir))
        _, template, _ = study_inputs(manifest, Path(study_dir))
        models = {
            "packaged": (template, REPORT_ACCURACY),
            "fitted": (result.model(), float(result.report_accuracy or 1.0)),
        }
        outcome = posterior_check(roads, models, CHECK_REPLICATES, np.random.default_rng(seed))
        stem = Path(path).with_suffix("")
        paths["check_json"] = write_check(outcome, stem.with_suffix(".check.json"))
        paths["check_plot"] = plot_check(outcome, stem.with_suffix(".check.png"))
        payload["check"] = {
            "distance": {name: m["distance"] for name, m in outcome["models"].items()},
            # the packaged setup's aware and free policies driven by packaged vs fitted drivers
            "aware_vs_free": aware_vs_free(
                {name: model for name, (model, _) in models.items()}, CHECK_EPISODES, seed
            ),
        }
    payload = with_paths(payload, paths)
    if as_json:
        click.echo(json.dumps(payload, default=str))
        return
    if check:
        for name, distance in payload["check"]["distance"].items():
            takeover = ", ".join(f"{k} {v:.3f}" for k, v in distance["takeover_rate_abs_difference"].items())
            click.echo(
                f"check {name}: takeover rate |diff| {takeover}; "
                f"TV trust change {distance['trust_change_tv']:.3f}, "
                f"final trust {distance['final_trust_tv']:.3f}, changes per episode "
                f"{distance['changes_per_episode_tv']:.3f}"
            )
        for row in payload["check"]["aware_vs_free"]:
            click.echo(
                f"{row['spec']} {row['condition']} with {counted(row['drivers'], 'driver')}: satisfaction "
                f"{row['satisfaction_rate']:.4f}, mean true trust {row['mean_trust']:.3f} "
                f"({counted(row['episodes'], 'episode')})"
            )
        click.echo(f"check: {paths['check_json']} and {paths['check_plot']}")
    click.echo(
        f"fitted by {result.method} on {counted(result.episodes, 'episode')} "
        f"({counted(result.transitions, 'road')} driven)"
        f"{f', report accuracy {result.report_accuracy:.3f}' if result.report_accuracy is not None else ''}"
        f"{f', EM {result.iterations} iterations' if result.method == 'em' else ''}"
    )
    click.echo(f"driver model written to {path}")
    if bootstrap:
        resampled = payload["bootstrap"]
        click.echo(f"bootstrap: {resampled['resamples']} resamples of participants "
                   f"({resampled['converged']} converged); 2.5-97.5 % percentile intervals of every "
                   f"takeover probability and expected trust change in {paths['bootstrap']}")
    if result.method == "em" and not result.converged:
        click.echo(f"warning: EM stopped at the iteration cap ({iterations}) before converging", err=True)
    for label, rows in (
        ("transition rows", result.sparse_rows()),
        ("takeover probabilities", result.sparse_takeover()),
    ):
        if rows:
            click.echo(f"unidentified {label} (too little data, kept at the prior/start): {len(rows)}")


def _type_count(types: str) -> int | None:
    """--types: an integer K in its range, or None for 'auto'."""
    if types == "auto":
        return None
    return Checked(ranges.TYPES).convert(types, None, None)


def fit_types(study_dir: Path, out: Path, options: FitOptions, fixed: int | None,
              warnings: list[str]) -> None:
    """`trustroute fit --types`: the mixture of `fixed` types (None: chosen by BIC), its BIC table and
    bootstrap, a driver-population file (`warnings`: what reading the study could not check, already
    said)."""
    import time

    import numpy as np
    from tqdm import tqdm

    from trustroute.analysis.fitting.mixture import (
        EMSettings,
        bootstrap_type_count,
        fit_mixture,
        mixture_population,
        select_types,
        study_observations,
    )
    from trustroute.app.populations import write_population as write_driver_population
    from trustroute.core.output_files import atomic_write_text

    types, max_types, restarts = options.types, options.max_types, options.restarts
    iterations, bootstrap, seed = options.iterations, options.bootstrap, options.seed
    shared_dynamics, as_json, quiet = options.shared_dynamics, options.as_json, options.quiet
    assert types is not None   # (fit calls this only with --types)
    rng = np.random.default_rng(seed)
    data, logs = study_observations(study_dir)
    obs, participants = data.observations, data.participants
    settings = EMSettings(restarts=restarts, iterations=iterations, shared_dynamics=shared_dynamics)
    if fixed is None:
        with tqdm(total=min(max_types, len(participants)), desc="fitting K = 1..", unit="K",
                  disable=bar_disable(not (quiet or as_json))) as bar:
            selection = select_types(data, max_types, rng, settings, progress=bar.update)
    else:
        from trustroute.analysis.fitting.mixture import TypeSelection

        fits = [fit_mixture(data, fixed, rng, settings)]
        selection = TypeSelection(fits=fits, chosen=fixed)
    best = selection.best
    command = "trustroute fit " + " ".join(
        [str(study_dir), "--types", types, *(["--max-types", str(max_types)] if fixed is None else []),
         "--restarts", str(restarts), "--iterations", str(iterations), "--seed", str(seed),
         *(["--shared-dynamics"] if shared_dynamics else []),
         *(["--bootstrap", str(bootstrap)] if bootstrap else [])])
    provenance = (f"fitted by `{command}` ({time.strftime('%Y-%m-%d', time.gmtime())}) on "
                  f"{counted(len(participants), 'participant')}, {counted(obs.episodes, 'episode')}, "
                  f"{counted(obs.steps, 'road')}: "
                  f"EM over a mixture of {best.n_types} driver models"
                  f"{' sharing their trust dynamics' if shared_dynamics else ''}, "
                  f"{'chosen by BIC (n = participants)' if fixed is None else 'K given'}; "
                  f"shared report accuracy {best.report_accuracy:.4f}")
    path = write_driver_population(mixture_population(best, str(study_dir), provenance), out)
    criterion = "BIC (n = participants)" if fixed is None else "given"
    payload: dict = {"types": best.n_types, "criterion": criterion, "warnings": warnings,
                     "fit": best.summary(), "provenance": provenance,
                     "responsibilities": {str(p): dict(zip(best.type_names(), row.tolist(), strict=True))
                                          for p, row in zip(best.participants, best.responsibilities,
                                                            strict=True)}}
    if fixed is None:
        payload["bic_table"] = selection.table()
    if bootstrap:
        with tqdm(total=bootstrap, desc="bootstrap", disable=bar_disable(not (quiet or as_json))) as bar:
            payload["bootstrap"] = bootstrap_type_count(logs, selection, max_types, bootstrap, rng, settings,
                                                        progress=bar.update, choose=fixed is None)
    details = out.with_suffix(".fit.json")
    atomic_write_text(details, json.dumps(payload, indent=1, default=str), "fit details",
                      "pass a writable path with --out")
    payload = with_paths(payload, {"population": path, "fit_details": details})
    if as_json:
        click.echo(json.dumps(payload, default=str))
        return
    if fixed is None:
        click.echo("K  loglik      params  BIC(n=participants)  dBIC    BIC(n=roads)  converged")
        for row in payload["bic_table"]:
            click.echo(f"{row['types']:<2} {row['loglik']:<11.2f} {row['free_parameters']:<7} "
                       f"{row['bic']:<20.2f} {row['delta_bic']:<7.2f} {row['bic_roads']:<13.2f} "
                       f"{row['restarts_converged']}")
    weights = ", ".join(f"{k} {v:.3f}" for k, v in best.summary()["weights"].items())
    click.echo(f"{counted(best.n_types, 'type')} ({payload['criterion']}): weights {weights}; EM "
               f"{best.iterations} iterations, {'converged' if best.converged else 'NOT converged'}")
    if bootstrap:
        b = payload["bootstrap"]
        if "chosen_types_frequency" in b:
            click.echo(f"bootstrap ({b['resamples']} resamples of participants): K chosen "
                       + ", ".join(f"{k}: {v}" for k, v in b["chosen_types_frequency"].items()))
        for name, w in b.get("weights", {}).items():
            click.echo(f"  {name} weight 95% percentile interval [{w['low']:.3f}, {w['high']:.3f}]")
    click.echo(f"driver population written to {path} (details: {details})")
    if not best.converged:
        click.echo(f"warning: EM stopped at the iteration cap ({iterations}) before converging", err=True)
