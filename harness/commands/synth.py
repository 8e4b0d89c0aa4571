"""`trustroute synth`, `trustroute baseline`, `trustroute evaluate`: policies and their values.

synth     synthesize a trust-aware policy with certified bounds (policies.synthesis) and write its file
baseline  the trust-free shortest route completing the spec's state-only task, and its exact value
evaluate  the exact satisfaction probability and expected final trust of any policy
          ("free", "aware" or a policy file), with the study's 20-junction fallback by default
"""

from __future__ import annotations

import click

from trustroute.analysis.formatting import finite_or_none
from trustroute.core.errors import InputError
from trustroute.harness.commands.options import HORIZON, JUNCTIONS, FiniteFloat
from trustroute.harness.commands.output import emit, json_option, quiet_option, with_paths
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.model.trust_pomdp import checked_belief_rule
from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER
from trustroute.policies.synthesis.settings import SynthesisSettings


def _load_problem(spec_path: str, town_path: str | None, driver_path: str | None):
    """The Problem (policies/belief/problem.py) of the files given: its case decided once."""
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_model import load_driver_model
    from trustroute.policies.belief.problem import problem
    from trustroute.policies.logic.spec import load_spec

    town = load_town(town_path)
    driver = load_driver_model(driver_path)
    spec = load_spec(spec_path, town, driver.n_trust, driver.source_path)
    return problem(town, driver, spec)


town_option = click.option("--town", "town_path", type=click.Path(), default=None,
                           help="Town file (default: the packaged town).")
driver_option = click.option("--driver", "driver_path", type=click.Path(), default=None,
                             help="Driver model file (default: the packaged model).")
rule_option = click.option("--belief-rule", type=click.Choice(["bayes", "paper"]), default="bayes",
                           show_default=True,
                           help="AV belief filter: exact Bayes, or the authors' released update.")


SYNTH_FOLDER = "synth"   # under the policy cache: what `synth` writes without --out


def default_out_path(spec_name: str, *key: str) -> str:
    """Where `synth` writes without --out: `<policy cache>/synth/<spec>-<16 hex>.json`, the hex a
    SHA-256 of the inputs' content hashes and the settings, so another problem never overwrites it
    (and nothing lands in the working directory)."""
    import hashlib
    import re

    from trustroute.core.cache import POLICIES, cache_dir
    from trustroute.core.output_files import check_output_file

    label = re.sub(r"[^A-Za-z0-9_.+-]", "_", spec_name)[:48].lstrip(".") or "spec"
    digest = hashlib.sha256("|".join(key).encode()).hexdigest()[:16]
    path = cache_dir(POLICIES) / SYNTH_FOLDER / f"{label}-{digest}.json"
    check_output_file(path, "--out", "policy file")
    path.parent.mkdir(parents=True, exist_ok=True)
    return str(path)


@click.command("synth")
@click.argument("spec_path", metavar="SPEC")
@town_option
@driver_option
@click.option("--tau", type=FiniteFloat(0.0, 1.0, open_minimum=True), default=1e-3, show_default=True,
              help="Target gap upper - lower.")
@click.option("--horizon", type=HORIZON, default=None, help="At most H junctions (default: unbounded).")
@click.option("--time-limit", type=FiniteFloat(0.0, 7 * 24 * 3600.0, open_minimum=True), default=60.0,
              show_default=True, help="Seconds for the whole command (its synthesis runs share them).")
@rule_option
@quiet_option
@click.option("--out", "out_path", type=click.Path(), default=None,
              help="Policy FILE to write (its arrays go beside it, same name with suffix .npz); "
                   "default: the policy cache's synth/ folder, printed.")
@click.option("--clusters", type=click.Choice(["auto", "on", "off"]), default="auto", show_default=True,
              help="Cluster policies (Bayes rule; docs/synthesis.md, \"Cluster policies\"): before the "
                   "search on large problems and after an unconverged one (auto), always first (on), "
                   "never (off).")
@click.option("--population", "population_path", type=click.Path(), default=None,
              help="Driver-population FILE: synthesize for its mixture of driver types "
                   "(docs/driver_types.md); instead of --driver.")
@click.option("--objective", type=click.Choice(["bayes", "robust"]), default="bayes", show_default=True,
              help="With --population: the prior-weighted value (bayes) or the worst type's (robust).")
@json_option
def synth(spec_path: str, town_path: str | None, driver_path: str | None, tau: float,
          horizon: int | None, time_limit: float, belief_rule: str, quiet: bool, out_path: str | None,
          clusters: str, population_path: str | None, objective: str, as_json: bool) -> None:
    """Synthesize a trust-aware policy for SPEC with certified bounds lower <= Pr_max <= upper."""
    if tau <= 0:
        raise InputError("--tau", "", f"tau must be positive, got {tau}", "pass e.g. --tau 1e-3")
    if horizon is not None and horizon < 1:
        raise InputError("--horizon", "", f"horizon must be at least 1, got {horizon}",
                         "pass a positive number of junctions or omit --horizon")
    from trustroute.core.output_files import check_output_file

    if out_path is not None:
        check_output_file(out_path, "--out", "policy file")
    if population_path is not None:
        if driver_path is not None:
            raise click.UsageError("give --driver or --population, not both (a population's types are "
                                   "full driver models)")
        if clusters != "auto":
            raise click.UsageError("--clusters applies to a single driver model (--driver), not to "
                                   "--population")
        _synth_population(spec_path, town_path, population_path, objective, tau, horizon, time_limit,
                          belief_rule, out_path, as_json, quiet)
        return
    if objective != "bayes":
        raise click.UsageError("--objective robust needs --population FILE (the types to be robust over)")
    problem = _load_problem(spec_path, town_path, driver_path)
    town, driver, spec, pomdp = problem.town, problem.driver, problem.spec, problem.pomdp
    out_path = out_path or default_out_path(spec.name, town.content_hash, driver.content_hash,
                                            spec.content_hash, f"H={horizon}", f"tau={tau}", belief_rule,
                                            f"clusters={clusters}", f"time_limit={time_limit}")
    from trustroute.policies.resolve import synthesis_progress
    from trustroute.policies.routing.files import save_policy
    from trustroute.policies.synthesis.result import SynthesisStats
    from trustroute.policies.synthesize_spec import synthesize_problem

    with synthesis_progress(f"synthesizing {spec.name}", not (as_json or quiet)) as on_iteration:
        result = synthesize_problem(problem,
                                    SynthesisSettings(tau=tau, time_limit=time_limit, horizon=horizon,
                                                      belief_rule=checked_belief_rule(belief_rule),
                                                      clusters=clusters),
                                    on_iteration=on_iteration)
    path = str(save_policy(result, out_path, town, driver, spec))
    from trustroute.policies.routing.files import array_path

    payload = with_paths({"spec": spec.name, "lower": result.lower, "upper": result.upper, "gap": result.gap,
                          "seconds": result.seconds, "tau": tau, "horizon": horizon,
                          "belief_rule": belief_rule, "stats": result.stats.to_dict()},
                         {"policy": path, "policy_arrays": array_path(path)})
    lines = [f"{spec.name}: {result.lower:.6f} <= Pr_max <= {result.upper:.6f} (gap {result.gap:.2e}, "
             f"{result.seconds:.1f} s)"]
    boxes = getattr(result.policy.table, "boxes", None)
    if boxes is not None and boxes.rows:
        lines.append(f"a cluster policy: {boxes.rows} box rows, beliefs enclosed in boxes "
                     "(docs/synthesis.md, \"Cluster policies\")")
    # (only the belief-MDP search reads labels at thresholds both ways)
    alternates = result.stats.threshold_alternates if isinstance(result.stats, SynthesisStats) else 0
    if alternates:
        # the returned policy's (a run's policy may not be the one returned)
        strict = result.stats.lower_strict_labels
        lines.append(f"{alternates} outcomes sit on a belief threshold (within rounding): L reads them "
                     f"the worse way, U the better; with this machine's labels the policy is worth at "
                     f"least {strict:.6f} (spec check warns about such thresholds)")
    if belief_rule == "paper":
        # L and U are about the authors' belief MDP (their filter drives beliefs and labels); a
        # study measures the real process: observations drawn from the Bayes posterior.
        from trustroute.policies.evaluation.trust_state import evaluate_joint as evaluate_policy
        from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP

        cap = horizon if horizon is not None else DEFAULT_JUNCTION_CAP
        real = evaluate_policy(pomdp, spec, result.policy,
                               EvaluationSettings(fallback_after=None, max_junctions=cap,
                                                  belief_rule="paper"))
        payload["bounds_refer_to"] = "the authors' belief MDP (--belief-rule paper)"
        payload["bayes_process_value"] = {"lower": real.lower, "upper": real.upper,
                                          "max_junctions": cap}
        lines.append("L and U refer to the authors' belief MDP (--belief-rule paper), not the real "
                     "process")
        lines.append(f"the policy's value under the real (Bayes) process within {cap} junctions: "
                     f"[{real.lower:.6f}, {real.upper:.6f}]")
    lines.append(f"policy written to {path}")
    emit(as_json, payload, lines)


def _synth_population(spec_path: str, town_path: str | None, population_path: str, objective: str,
                      tau: float, horizon: int | None, time_limit: float, belief_rule: str,
                      out_path: str | None, as_json: bool, quiet: bool = False) -> None:
    """`synth --population`: the Bayes or robust objective over a population's driver types; past
    2 s (policies/resolve.py's PROGRESS_AFTER), a line per finished synthesis run with its bounds
    on stderr."""
    from trustroute.networks.town import load_town
    from trustroute.participants.driver_population import load_driver_population
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.resolve import is_objective, phase_lines, synthesis_progress
    from trustroute.policies.routing.files import array_path, save_policy
    from trustroute.policies.synthesis.population import document_entries, policy_name, summary
    from trustroute.policies.synthesize_spec import synthesize_for_population

    if not is_objective(objective):
        raise ValueError(f"unknown objective {objective!r}; use 'bayes' or 'robust'")
    town = load_town(town_path)
    population = load_driver_population(population_path)
    spec = load_spec(spec_path, town, population.types[0].model.n_trust, population_path)
    out_path = out_path or default_out_path(spec.name, town.content_hash, population.content_hash,
                                            spec.content_hash, objective, f"H={horizon}", f"tau={tau}",
                                            belief_rule, f"time_limit={time_limit}")
    with synthesis_progress(f"synthesizing {spec.name} ({objective}, {population.n_types} types)",
                            not (as_json or quiet)) as on_iteration:
        found = synthesize_for_population(town, population, spec, objective,
                                          SynthesisSettings(tau=tau, time_limit=time_limit, horizon=horizon,
                                                            belief_rule=checked_belief_rule(belief_rule)),
                                          population_source=population_path,
                                          on_iteration=on_iteration,
                                          on_phase=phase_lines("synth", not (as_json or quiet)))
    result = found.result
    path = str(save_policy(result, out_path, town, found.pomdp.driver, found.spec,
                           population=document_entries(found), name=policy_name(found)))
    population_summary = summary(found)
    population_summary.update({"file": population_path, "content_hash": population.content_hash})
    payload = with_paths({"spec": spec.name, "lower": found.lower, "upper": found.upper, "gap": found.gap,
                          "seconds": found.seconds, "tau": tau, "horizon": horizon,
                          "belief_rule": belief_rule, "population": population_summary,
                          "stats": result.stats.to_dict()},
                         {"policy": path, "policy_arrays": array_path(path)})
    what = "P(satisfied), prior-weighted" if objective == "bayes" else "worst type's P(satisfied)"
    lines = [f"{spec.name} ({population.n_types} driver types, objective {objective}): "
             f"{found.lower:.6f} <= max {what} <= {found.upper:.6f} (gap {found.gap:.2e}, "
             f"{found.seconds:.1f} s)"]
    lines.append("returned policy per type (exact, true driver of that type): " + "; ".join(
        f"{v.name} (weight {v.weight:g}) [{v.lower:.6f}, {v.upper:.6f}]" for v in found.type_values))
    mixture = found.mixture_value
    lines.append(f"returned policy under the type prior: [{mixture[0]:.6f}, {mixture[1]:.6f}]; worst type "
                 f"{found.worst_type_value:.6f}; AV type prior {', '.join(f'{p:g}' for p in found.prior)}")
    if objective == "robust":
        worst_bayes = min(v.lower for v in found.bayes_type_values)
        lines.append(f"Bayes-optimal synthesis beside it: {found.bayes_lower:.6f} <= prior-weighted <= "
                     f"{found.bayes_upper:.6f}, its worst type {worst_bayes:.6f}; robust value certified "
                     f">= {found.lower:.6f} (best of {len(found.candidates)} candidate priors), <= "
                     f"{found.upper:.6f}")
    lines.append(f"policy written to {path}")
    emit(as_json, payload, lines)


@click.command("baseline")
@click.argument("spec_path", metavar="SPEC")
@town_option
@driver_option
@rule_option
@json_option
def baseline(spec_path: str, town_path: str | None, driver_path: str | None, belief_rule: str,
             as_json: bool) -> None:
    """The trust-free baseline for SPEC: shortest route completing its state-only task."""
    from trustroute.policies.evaluation.plain import evaluate as evaluate_policy
    from trustroute.policies.routing.free import baseline_route, trust_free_policy

    problem = _load_problem(spec_path, town_path, driver_path)
    town, spec, pomdp = problem.town, problem.spec, problem.pomdp
    route = baseline_route(town, spec)
    value = evaluate_policy(pomdp, spec, trust_free_policy(town, spec),
                            EvaluationSettings(fallback_after=None,
                                               belief_rule=checked_belief_rule(belief_rule)))
    payload = {"spec": spec.name, "route": route, "length_m": town.route_length(route),
               "junctions": len(route) - 1, "satisfaction_probability": value.satisfaction_probability,
               "lower": value.lower, "upper": value.upper,
               "expected_final_trust": finite_or_none(value.expected_final_trust), "belief_rule": belief_rule}
    emit(as_json, payload, [
        f"{spec.name} trust-free route ({len(route) - 1} junctions, {payload['length_m']:.0f} m): "
        + " ".join(route),
        f"P(satisfied) = {value.satisfaction_probability:.6f}, E[final trust] = "
        f"{value.expected_final_trust:.4f}"])


population_option = click.option(
    "--population", "population_path", type=click.Path(), default=None,
    help="Driver-population FILE (instead of --driver): the AV filters with its type-aware model and "
         "the drivers are its mixture; POLICY may then be 'robust' or 'bayes' (docs/driver_types.md).")


@click.command("evaluate")
@click.argument("spec_path", metavar="SPEC")
@click.argument("policy_name", metavar="POLICY")
@town_option
@driver_option
@population_option
@click.option("--fallback-after", type=JUNCTIONS, default=DEFAULT_FALLBACK_AFTER, show_default=True,
              help="Switch to the shortest completion after this many junctions.")
@click.option("--no-fallback", is_flag=True, help="Evaluate the policy without the fallback rule.")
@click.option("--max-junctions", type=JUNCTIONS, default=None,
              help=f"Episode cap (default {DEFAULT_JUNCTION_CAP}).")
@rule_option
@click.option("--cache-dir", type=click.Path(), default=None,
              help="Where 'aware' policies are cached (default: $XDG_CACHE_HOME/trustroute/policies, "
              "XDG_CACHE_HOME defaulting to ~/.cache).")
@click.option("--max-nodes", type=click.IntRange(min=1), default=None,
              help="Follow at most this many (the likeliest) histories per junction; the rest widen "
                   "[lower, upper] (default: 5,000 for specs with trust-state atoms, 2,000,000 "
                   "otherwise).")
@click.option("--time-limit", type=FiniteFloat(0.0, 7 * 24 * 3600.0, open_minimum=True), default=None,
              help="Seconds, for specs with trust-state atoms: histories still open then widen "
                   "[lower, upper] (default: none).")
@quiet_option
@json_option
def evaluate(spec_path: str, policy_name: str, town_path: str | None, driver_path: str | None,
             population_path: str | None, fallback_after: int, no_fallback: bool,
             max_junctions: int | None, belief_rule: str, cache_dir: str | None,
             max_nodes: int | None, time_limit: float | None, quiet: bool, as_json: bool) -> None:
    """Certified probability that POLICY ("free", "aware" or a file) satisfies SPEC, and final trust.

    "aware" is synthesized for a horizon of 20 junctions (the study's rule) and cached. The result
    is exact (lower = upper) unless histories were pruned; their live mass is the width.
    """
    # Specs without trust-state atoms go on to policies.evaluation.plain (the same results bit for bit).
    from trustroute.policies.evaluation.trust_state import evaluate_joint as evaluate_policy

    if fallback_after < 0:
        raise InputError("--fallback-after", "", f"must be >= 0, got {fallback_after}",
                         "pass a number of junctions or --no-fallback")
    cap = DEFAULT_JUNCTION_CAP if max_junctions is None else max_junctions
    if cap < 0:
        raise InputError("--max-junctions", "", f"must be >= 0, got {cap}", "pass e.g. 60")
    if cache_dir is not None:
        from trustroute.core.output_files import check_output_dir

        check_output_dir(cache_dir, "--cache-dir", "policy cache")
    after = None if no_fallback else fallback_after
    if population_path is not None:
        if driver_path is not None:
            raise click.UsageError("give --driver or --population, not both")
        if max_nodes is not None or time_limit is not None:
            raise click.UsageError("--max-nodes and --time-limit are not used with --population")
        _evaluate_population(spec_path, policy_name, town_path, population_path, after, cap, belief_rule,
                             cache_dir, as_json, quiet)
        return
    problem = _load_problem(spec_path, town_path, driver_path)
    town, driver, spec, pomdp = problem.town, problem.driver, problem.spec, problem.pomdp
    from trustroute.policies.resolve import resolve_policy

    if policy_name in ("robust", "bayes"):
        raise click.UsageError(f"POLICY '{policy_name}' needs --population FILE (the driver types)")
    policy = resolve_policy(policy_name, town, driver, spec, cache_dir, progress=not (as_json or quiet))
    if time_limit is not None and not problem.dfa_hidden:
        raise click.UsageError("--time-limit applies to specs with trust-state atoms only (the others "
                               "are evaluated exactly in full)")
    value = evaluate_policy(pomdp, spec, policy,
                            EvaluationSettings(fallback_after=after, max_junctions=cap,
                                               belief_rule=checked_belief_rule(belief_rule),
                                               max_nodes=max_nodes, time_limit=time_limit))
    payload = value.to_dict()
    payload["spec"] = spec.name
    payload["expected_final_trust"] = finite_or_none(value.expected_final_trust)
    payload["expected_junctions"] = finite_or_none(value.expected_junctions)
    lines = [
        f"{spec.name} / {value.policy}: P(satisfied) in [{value.lower:.6f}, {value.upper:.6f}], "
        f"E[final trust] = {value.expected_final_trust:.4f}, E[junctions] = "
        f"{value.expected_junctions:.2f}, P(fallback fired) = {value.fallback_probability:.4f}",
        "episode ends: " + ", ".join(f"{k} {v:.4f}" for k, v in value.end_mass.items())]
    if value.pruning is not None:
        lines.append(_pruning_line(value))
    emit(as_json, payload, lines)


def _pruning_line(value) -> str:
    """What the joint unfolding's limits cut: the width of [lower, upper] and its sources."""
    pruning = value.pruning
    if not any(pruning["pruned_nodes"].values()):
        return f"exact: no history pruned (at most {pruning['max_nodes']:,} per junction)"
    parts = {"below_threshold": f"below {pruning['prune_below']:g}",
             "beyond_budget": f"beyond {pruning['max_nodes']:,} per junction",
             "past_deadline": f"open after {pruning['time_limit']} s"}
    cuts = ", ".join(f"{pruning['pruned_nodes'][k]:,} {label} (mass {pruning['pruned_mass'][k]:.2e})"
                     for k, label in parts.items() if pruning["pruned_nodes"][k])
    return (f"bracket width {value.gap:.2e} = live mass of the pruned histories, from junction "
            f"{pruning['first_pruned_level']}: {cuts}")


def load_population_routing(spec_path: str, town_path: str | None, population_path: str,
                            policy_name: str, cache_dir: str | None, progress: bool = False):
    """(town, population, spec, policy, lifted model, lifted spec) for routing with a driver
    population: POLICY "free", "robust"/"bayes" (synthesized and cached) or a policy file made for
    this population and spec (another one: InputError, one line, exit 2)."""
    from pathlib import Path

    from trustroute.networks.town import load_town
    from trustroute.participants.driver_population import load_driver_population
    from trustroute.policies.belief.driver_types import lift_population, lift_spec
    from trustroute.policies.logic.spec import load_spec
    from trustroute.policies.resolve import population_policy
    from trustroute.policies.routing.files import load_population_policy
    from trustroute.policies.routing.free import trust_free_policy

    town = load_town(town_path)
    population = load_driver_population(population_path)
    spec = load_spec(spec_path, town, population.types[0].model.n_trust, population_path)
    if policy_name in ("robust", "bayes"):
        policy, model, lifted_spec = population_policy(town, population, spec, policy_name, cache_dir,
                                                       population_source=population_path,
                                                       progress=progress)
    elif policy_name == "free":
        model, lifted_spec = lift_population(population), lift_spec(spec, population, population_path)
        policy = trust_free_policy(town, lifted_spec)
    elif policy_name == "aware":
        raise click.UsageError("with --population, POLICY is 'free', 'robust', 'bayes' or a policy file")
    else:
        if not Path(policy_name).exists():
            raise InputError(policy_name, "", "not a policy file and not 'free', 'robust' or 'bayes'",
                             "pass a policy file written by trustroute synth --population")
        policy, model, lifted_spec = load_population_policy(policy_name, town, population, spec,
                                                            population_path)
    return town, population, spec, policy, model, lifted_spec


def _evaluate_population(spec_path: str, policy_name: str, town_path: str | None, population_path: str,
                         fallback_after: int | None, cap: int, belief_rule: str, cache_dir: str | None,
                         as_json: bool, quiet: bool) -> None:
    """`evaluate --population`: exact value over the mixture and per type."""
    from trustroute.policies.belief.problem import problem as routing_problem
    from trustroute.policies.evaluation.plain import evaluate as evaluate_policy
    from trustroute.policies.evaluation.trust_state import evaluate_joint_by_type
    from trustroute.policies.synthesis.population import TypeValue, per_type_values

    rule = checked_belief_rule(belief_rule)

    town, population, spec, policy, model, lifted_spec = load_population_routing(
        spec_path, town_path, population_path, policy_name, cache_dir, progress=not (as_json or quiet))
    found = routing_problem(town, population, spec, population_path)
    pomdp = found.pomdp
    if found.dfa_hidden:
        # The DFA state is hidden: one unfolding over ((type, trust), q) gives every type's value.
        value, bounds = evaluate_joint_by_type(pomdp, lifted_spec, policy,
                                               EvaluationSettings(fallback_after=fallback_after,
                                                                  max_junctions=cap, belief_rule=rule))
        types = tuple(TypeValue(t.name, float(t.weight), lower, upper)
                      for t, (lower, upper) in zip(population.types, bounds, strict=True))
    else:
        value = evaluate_policy(pomdp, lifted_spec, policy,
                                EvaluationSettings(fallback_after=fallback_after, max_junctions=cap,
                                                   belief_rule=rule))
        types = per_type_values(pomdp, lifted_spec, policy, population, cap, rule, fallback_after)
    payload = value.to_dict()
    payload["spec"] = spec.name
    payload["expected_final_trust"] = finite_or_none(value.expected_final_trust)
    payload["expected_junctions"] = finite_or_none(value.expected_junctions)
    payload["population"] = {"file": population_path, "content_hash": population.content_hash,
                             "type_values": [t.to_dict() for t in types]}
    emit(as_json, payload, [
        f"{spec.name} / {value.policy} over the population's {population.n_types} driver types: "
        f"P(satisfied) in [{value.lower:.6f}, {value.upper:.6f}], E[final trust] = "
        f"{value.expected_final_trust:.4f}",
        "per type: " + "; ".join(f"{t.name} (weight {t.weight:g}) [{t.lower:.6f}, {t.upper:.6f}]"
                                 for t in types)])
