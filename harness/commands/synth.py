"""`trustroute synth`, `trustroute baseline`, `trustroute evaluate`: policies and their values.

synth     synthesize a trust-aware policy with certified bounds (policies.synthesis) and write its file
baseline  the trust-free shortest route completing the spec's state-only task, and its exact value
evaluate  the exact satisfaction probability and expected final trust of any policy
          ("free", "aware" or a policy file), with the study's 20-junction fallback by default
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import click

from trustroute.analysis.formatting import finite_or_none
from trustroute.app.problem import load_problem
from trustroute.core import defaults, ranges
from trustroute.core.wording import counted, interval, lower_text, outward
from trustroute.harness.commands.inputs import (
    POPULATION_GIVEN,
    driver_field,
    driver_option,
    spec_argument,
    town_field,
    town_option,
)
from trustroute.harness.commands.option_groups import option, option_decorator, takes
from trustroute.harness.commands.options import Checked, synthesis_time_left
from trustroute.harness.commands.output import emit, json_flag, json_option, quiet_flag, with_paths

if TYPE_CHECKING:
    from trustroute.app.synthesis import EvaluationSettings, SynthesisSettings


def rule_field() -> Any:
    return option("--belief-rule", type=click.Choice(["bayes", "paper"]), default=defaults.BELIEF_RULE,
                  show_default=True, help="AV belief filter: exact Bayes, or the authors' released update.")


def command_time_limit(help: str, **attrs: Any) -> Any:
    """--time-limit in seconds, at most a week (the range the API checks, `check_time_limit`)."""
    return option("--time-limit", type=Checked(ranges.TIME_LIMIT), help=help, **attrs)


rule_option = option_decorator("belief_rule", rule_field())


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


@dataclass(frozen=True)
class SynthOptions:
    """`trustroute synth`'s options, in the order --help lists them."""

    town_path: str | None = town_field()
    driver_path: str | None = driver_field()
    tau: float = option("--tau", type=Checked(ranges.TAU), default=defaults.TAU,
                        show_default=True, help="Target gap upper - lower.")
    horizon: int | None = option("--horizon", type=Checked(ranges.HORIZON), default=defaults.SYNTH_HORIZON,
                                 help="At most H junctions (default: unbounded).")
    time_limit: float = command_time_limit("Seconds for the whole command (its synthesis runs share them).",
                                           default=defaults.TIME_LIMIT, show_default=True)
    work_limit: int | None = option(
        "--work-limit", type=Checked(ranges.WORK_LIMIT), default=defaults.WORK_LIMIT,
        help="Units of work for the whole command (node expansions, sweeps, ...): a stop that does not "
             "depend on the machine or its load, so the same inputs give the same policy; "
             '--time-limit still applies (default: none; docs/synthesis.md, "Work limit").')
    node_budget: int = option(
        "--node-budget", type=Checked(ranges.NODE_BUDGET), default=defaults.NODE_BUDGET, show_default=True,
        help="The most nodes the belief-MDP search holds (specs without trust-state atoms), about 1 kB "
             "of memory each: past them it stops, whatever its limits (it says so: \"stopped_by\": "
             "\"node budget\").")
    belief_rule: str = rule_field()
    quiet: bool = quiet_flag()
    out_path: str | None = option(
        "--out", type=click.Path(), default=None,
        help="Policy FILE to write (its arrays go beside it, same name with suffix .npz); "
             "default: the policy cache's synth/ folder, printed.")
    clusters: str = option(
        "--clusters", type=click.Choice(defaults.CLUSTER_MODES), default=defaults.CLUSTERS, show_default=True,
        help="Cluster policies (Bayes rule; docs/synthesis.md, \"Cluster policies\"): before the "
             "search on large problems and after an unconverged one (auto), always first (on), "
             "never (off).")
    population_path: str | None = option(
        "--population", type=click.Path(), default=None,
        help=f"{POPULATION_GIVEN}: synthesize for its mixture of driver types "
             "(docs/driver_types.md); instead of --driver.")
    objective: str = option(
        "--objective", type=click.Choice(["bayes", "robust"]), default=defaults.OBJECTIVE, show_default=True,
        help="With --population: the prior-weighted value (bayes) or the worst type's (robust).")
    as_json: bool = json_flag()

    def settings(self) -> SynthesisSettings:
        """The synthesis's settings (the whole command's --time-limit; `synth` gives the search
        what is left of it)."""
        from trustroute.app.synthesis import SynthesisSettings, belief_rule_named

        return SynthesisSettings(tau=self.tau, time_limit=self.time_limit, work_limit=self.work_limit,
                                 horizon=self.horizon, node_budget=self.node_budget,
                                 belief_rule=belief_rule_named(self.belief_rule), clusters=self.clusters,
                                 progress=not (self.as_json or self.quiet))


@click.command("synth")
@spec_argument()
@takes(options=SynthOptions)
def synth(spec_path: str, options: SynthOptions) -> None:
    """Synthesize a trust-aware policy for SPEC with certified bounds lower <= Pr_max <= upper."""
    from trustroute.app.synthesis import (
        check_policy_out,
        check_synthesis_options,
        policy_arrays,
        synthesize_single,
    )

    settings, out_path = options.settings(), options.out_path
    if out_path is not None:
        check_policy_out(out_path, {"SPEC": spec_path, "--town": options.town_path,
                                    "--driver": options.driver_path, "--population": options.population_path})
    check_synthesis_options(options.population_path is not None, options.objective, options.clusters)
    problem = load_problem(spec_path, options.town_path, options.driver_path, options.population_path)
    if problem.population is not None:
        _synth_population(problem, options.objective, settings, out_path, options.as_json)
        return
    town, driver, spec = problem.town, problem.driver, problem.spec
    out_path = out_path or default_out_path(spec.name, town.content_hash, driver.content_hash,
                                            spec.content_hash, f"H={options.horizon}", f"tau={options.tau}",
                                            options.belief_rule, f"clusters={options.clusters}",
                                            f"time_limit={options.time_limit}",
                                            *_work_key(options.work_limit, options.node_budget))
    result = synthesize_single(problem, replace(settings, time_limit=synthesis_time_left(options.time_limit)),
                               out_path)
    path = str(out_path)
    from trustroute.app.synthesis import bounds_notes

    payload = with_paths({"spec": spec.name, "lower": result.lower, "upper": result.upper, "gap": result.gap,
                          "seconds": result.seconds, "tau": options.tau, "horizon": options.horizon,
                          "belief_rule": options.belief_rule, "stopped_by": result.stopped_by,
                          "stats": result.stats.to_dict(),
                          "fallback_only": _warn_fallback_only(f"the policy for {spec.name}", result.policy,
                                                               result.stats.converged)},
                         {"policy": path, "policy_arrays": policy_arrays(path)})
    low, high = outward(result.lower, result.upper, 6)
    lines = [f"{spec.name}: {low} <= Pr_max <= {high} (gap {result.gap:.2e}, "
             f"{result.seconds:.1f} s)"]
    lines += bounds_notes(result, options.tau)
    if options.belief_rule == "paper":
        # L and U are about the authors' belief MDP (their filter drives beliefs and labels); a
        # study measures the real process: observations drawn from the Bayes posterior.
        from trustroute.app.synthesis import EvaluationSettings, evaluate_single

        cap = options.horizon if options.horizon is not None else defaults.JUNCTION_CAP
        real = evaluate_single(problem, result.policy, EvaluationSettings(
            fallback_after=None, max_junctions=cap, belief_rule="paper"))
        payload["bounds_refer_to"] = "the authors' belief MDP (--belief-rule paper)"
        payload["bayes_process_value"] = {"lower": real.lower, "upper": real.upper,
                                          "max_junctions": cap}
        lines.append("L and U refer to the authors' belief MDP (--belief-rule paper), not the real "
                     "process")
        lines.append(f"the policy's value under the real (Bayes) process within {cap} junctions: "
                     f"{interval(real.lower, real.upper)}")
    lines.append(f"policy written to {path}")
    emit(options.as_json, payload, lines)


def _work_key(work_limit: int | None, node_budget: int) -> tuple[str, ...]:
    """The work limit's and the node budget's part of the default policy path's key (none with
    their defaults, so the paths of runs that keep them stay what they were)."""
    key = () if work_limit is None else (f"work_limit={work_limit}",)
    return key + (() if node_budget == defaults.NODE_BUDGET else (f"node_budget={node_budget}",))


def _warn_fallback_only(what: str, policy, converged: bool, outranked: bool = False) -> bool:
    """Whether `policy` is only its fallback (no decision row); if so, one line on stderr."""
    from trustroute.app.synthesis import fallback_only, fallback_warning

    fallback = fallback_only(policy)
    if fallback is not None:
        click.echo(fallback_warning(what, fallback, converged, outranked), err=True)
    return fallback is not None


def _synth_population(problem, objective: str, settings, out_path: str | None, as_json: bool) -> None:
    """`synth --population`: the Bayes or robust objective over a population's driver types; past
    2 s (policies/resolve.py's PROGRESS_AFTER), a line per finished synthesis run with its bounds
    on stderr."""
    from trustroute.app.synthesis import (
        policy_arrays,
        population_summary,
        reached_tau,
        stop_notes,
        synthesize_population,
    )

    town, population, spec = problem.town, problem.population, problem.given_spec
    tau, horizon, time_limit = settings.tau, settings.horizon, settings.time_limit
    out_path = out_path or default_out_path(spec.name, town.content_hash, population.content_hash,
                                            spec.content_hash, objective, f"H={horizon}", f"tau={tau}",
                                            settings.belief_rule, f"time_limit={time_limit}",
                                            *_work_key(settings.work_limit, settings.node_budget))
    # the command's limit, less what start-up and reading the inputs took (the out path's key keeps it)
    found = synthesize_population(problem, objective,
                                  replace(settings, time_limit=synthesis_time_left(time_limit)), out_path)
    result = found.result
    path = str(out_path)
    summary = population_summary(found)
    summary.update({"file": population.source_path, "content_hash": population.content_hash})
    payload = with_paths({"spec": spec.name, "lower": found.lower, "upper": found.upper, "gap": found.gap,
                          "seconds": found.seconds, "tau": tau, "horizon": horizon,
                          "belief_rule": settings.belief_rule, "stopped_by": result.stopped_by,
                          "population": summary,
                          "stats": result.stats.to_dict(),
                          "fallback_only": _warn_fallback_only(
                              f"the {objective} policy for {spec.name}", result.policy, found.gap <= tau,
                              any(c.get("rows", 0) > 0 for c in found.candidates))},
                         {"policy": path, "policy_arrays": policy_arrays(path)})
    lines = population_lines(spec.name, population.n_types, objective, found,
                             summary["bayes"]["worst_type_value"])
    lines += stop_notes(result, tau, reached_tau(found, tau))
    lines.append(f"policy written to {path}")
    emit(as_json, payload, lines)


def population_lines(spec_name: str, n_types: int, objective: str, found, worst_bayes: float) -> list[str]:
    """A population synthesis' bounds as text (`found`: its PopulationSynthesis; `worst_bayes`: the
    worst type's value of the Bayes policy beside a robust one), every bound rounded outward
    (core/wording.py) so that no printed figure claims more than was certified."""
    what = "P(satisfied), prior-weighted" if objective == "bayes" else "worst type's P(satisfied)"
    low, high = outward(found.lower, found.upper, 6)
    lines = [f"{spec_name} ({n_types} driver types, objective {objective}): "
             f"{low} <= max {what} <= {high} (gap {found.gap:.2e}, {found.seconds:.1f} s)"]
    lines.append("returned policy per type (true driver of that type): "
                 + "; ".join(type_value_text(v) for v in found.type_values))
    lines.append(f"returned policy under the population's weights: {interval(*found.mixture_value)}; "
                 f"worst type {lower_text(found.worst_type_value)}; {prior_text(found)}")
    if objective == "robust":
        bayes_low, bayes_high = outward(found.bayes_lower, found.bayes_upper, 6)
        lines.append(f"Bayes-optimal synthesis beside it: {bayes_low} <= prior-weighted <= {bayes_high}, "
                     f"its worst type {lower_text(worst_bayes)}; robust value certified >= {low} (best of "
                     f"{counted(len(found.candidates), 'candidate prior')}{candidates_left_out(found)}), "
                     f"<= {high}")
    return lines


def type_value_text(value) -> str:
    """One type's value (a TypeValue) as `synth` and `evaluate --population` print it: "exact" only
    where its evaluation cut no history (`TypeValue.exact`: lower and upper differ by the certified
    rounding alone), else "certified"; rounded outward either way."""
    kind = "exact" if value.exact else "certified"
    return f"{value.name} (weight {value.weight:g}) {kind} {interval(value.lower, value.upper)}"


def prior_text(found) -> str:
    """The type prior the returned policy's table was built for, told apart from the AV's belief:
    the AV always filters with the population's weights, a candidate prior's table reading its
    belief reweighted to that prior (docs/driver_types.md, "The robust objective")."""
    weights = [float(w) for w in found.population.weights]
    shown = ", ".join(f"{w:g}" for w in weights)
    if all(abs(p - w) <= 1e-12 for p, w in zip(found.prior, weights, strict=True)):
        return f"policy table built for the population's weights {shown}, with which the AV filters"
    prior = ", ".join(f"{p:g}" for p in found.prior)
    return (f"policy table built for the type prior {prior}; the AV filters with the population's "
            f"weights {shown}, its belief reweighted to that prior for the table")


def candidates_left_out(found) -> str:
    """What the robust summary adds on the candidate priors not run: those left out once the best
    was within tau of the bound, those skipped for want of time."""
    text = ""
    if found.candidates_not_needed:
        text += f"; {found.candidates_not_needed} more not run, the best being within tau of the bound"
    if found.candidates_skipped:
        text += f"; {found.candidates_skipped} more skipped, the limit leaving no time for their runs"
    return text


@click.command("baseline")
@spec_argument()
@town_option
@driver_option
@rule_option
@json_option
def baseline(spec_path: str, town_path: str | None, driver_path: str | None, belief_rule: str,
             as_json: bool) -> None:
    """The trust-free baseline for SPEC: shortest route completing its state-only task."""
    from trustroute.app.synthesis import baseline as trust_free_baseline
    from trustroute.app.synthesis import belief_rule_named

    problem = load_problem(spec_path, town_path, driver_path)
    spec = problem.spec
    found = trust_free_baseline(problem, belief_rule_named(belief_rule))
    route, value = found.route, found.value
    payload = {"spec": spec.name, "route": route, "length_m": found.length_m,
               "junctions": len(route) - 1, "satisfaction_probability": value.satisfaction_probability,
               "lower": value.lower, "upper": value.upper,
               "expected_final_trust": finite_or_none(value.expected_final_trust), "belief_rule": belief_rule}
    emit(as_json, payload, [
        f"{spec.name} trust-free route ({counted(len(route) - 1, 'junction')}, {payload['length_m']:.0f} m): "
        + " ".join(route),
        f"P(satisfied) in {interval(value.lower, value.upper)}, E[final trust] = "
        f"{value.expected_final_trust:.4f}"])


@dataclass(frozen=True)
class EvaluateOptions:
    """`trustroute evaluate`'s options, in the order --help lists them."""

    town_path: str | None = town_field()
    driver_path: str | None = driver_field()
    population_path: str | None = option(
        "--population", type=click.Path(), default=None,
        help=f"{POPULATION_GIVEN} (instead of --driver): the AV filters with its type-aware model and "
             "the drivers are its mixture; POLICY may then be 'robust' or 'bayes' (docs/driver_types.md).")
    fallback_after: int = option("--fallback-after", type=Checked(ranges.FALLBACK_AFTER),
                                 default=defaults.FALLBACK_AFTER, show_default=True,
                                 help="Switch to the shortest completion after this many junctions.")
    no_fallback: bool = option("--no-fallback", is_flag=True,
                               help="Evaluate the policy without the fallback rule.")
    max_junctions: int | None = option("--max-junctions", type=Checked(ranges.MAX_JUNCTIONS), default=None,
                                       help=f"Episode cap (default {defaults.JUNCTION_CAP}).")
    belief_rule: str = rule_field()
    cache_dir: str | None = option(
        "--cache-dir", type=click.Path(), default=None,
        help="Where 'aware' policies are cached (default: $XDG_CACHE_HOME/trustroute/policies, "
             "XDG_CACHE_HOME defaulting to ~/.cache).")
    max_nodes: int | None = option(
        "--max-nodes", type=Checked(ranges.MAX_NODES), default=None,
        help="Follow at most this many (the likeliest) histories per junction; the rest widen "
             "[lower, upper] (default: 5,000 for specs with trust-state atoms, 2,000,000 otherwise).")
    time_limit: float | None = command_time_limit(
        "Seconds, for specs with trust-state atoms: histories still open then widen [lower, upper] "
        "(default: none).", default=None)
    quiet: bool = quiet_flag()
    as_json: bool = json_flag()

    def settings(self) -> EvaluationSettings:
        """The evaluation's settings, each limit checked (a usage error names its option)."""
        from trustroute.app.synthesis import EvaluationSettings, belief_rule_named

        cap = defaults.JUNCTION_CAP if self.max_junctions is None else self.max_junctions
        if self.cache_dir is not None:
            from trustroute.core.output_files import check_output_dir

            check_output_dir(self.cache_dir, "--cache-dir", "policy cache")
        return EvaluationSettings(fallback_after=None if self.no_fallback else self.fallback_after,
                                  max_junctions=cap, belief_rule=belief_rule_named(self.belief_rule),
                                  max_nodes=self.max_nodes, time_limit=self.time_limit)


@click.command("evaluate")
@spec_argument()
@click.argument("policy_name", metavar="POLICY")
@takes(options=EvaluateOptions)
def evaluate(spec_path: str, policy_name: str, options: EvaluateOptions) -> None:
    """Certified probability that POLICY ("free", "aware" or a file) satisfies SPEC, and final trust.

    "aware" is synthesized for a horizon of 20 junctions (the study's rule) and cached. The result
    is exact (lower = upper) unless histories were pruned; their live mass is the width.
    """
    from trustroute.app.policy import PolicySettings, policy_for
    from trustroute.app.synthesis import evaluate_problem

    settings = options.settings()
    problem = load_problem(spec_path, options.town_path, options.driver_path, options.population_path)
    making = PolicySettings(cache_dir=options.cache_dir, progress=not (options.as_json or options.quiet))
    value = evaluate_problem(problem, lambda: policy_for(problem, policy_name, making), settings)
    payload, lines = _evaluation_output(problem, value, f"policy {policy_name}")
    emit(options.as_json, payload, lines)


def _evaluation_output(problem, value, what: str) -> tuple[dict, list[str]]:
    """`evaluate`'s JSON and text of `value` (an EvaluationOutcome of the policy `what`): the JSON is
    its `to_dict()` with the per-type values (`type_values`, a population's) moved under
    "population" and the fallback it only is marked (`_mark_fallback_only`); the text gives the
    value over the mixture and per type, else the episode ends and what pruning cut."""
    spec = problem.given_spec
    payload = value.to_dict()
    types, fallback = payload.pop("type_values", None), payload.pop("fallback_only", None)
    payload["spec"] = spec.name
    payload["expected_final_trust"] = finite_or_none(value.expected_final_trust)
    payload["expected_junctions"] = finite_or_none(value.expected_junctions)
    if types is not None:
        population = problem.population
        payload["population"] = {"file": population.source_path, "content_hash": population.content_hash,
                                 "type_values": types}
        lines = [
            f"{spec.name} / {value.policy} over the population's {population.n_types} driver types: "
            f"P(satisfied) in {interval(value.lower, value.upper)}, E[final trust] = "
            f"{value.expected_final_trust:.4f}",
            "per type: " + "; ".join(type_value_text(t) for t in value.type_values)]
    else:
        lines = [
            f"{spec.name} / {value.policy}: P(satisfied) in {interval(value.lower, value.upper)}, "
            f"E[final trust] = {value.expected_final_trust:.4f}, E[junctions] = "
            f"{value.expected_junctions:.2f}, P(fallback fired) = {value.fallback_probability:.4f}",
            "episode ends: " + ", ".join(f"{k} {v:.4f}" for k, v in value.end_mass.items())]
        if value.pruning is not None:
            lines.append(_pruning_line(value))
    _mark_fallback_only(payload, what, fallback)
    return payload, lines


def _mark_fallback_only(payload: dict, what: str, fallback: str | None) -> None:
    """A synthesized policy that is only its fallback (`fallback`: what drives, in words, as the
    evaluation's `to_dict()` gives it; None otherwise): one line on stderr and `"fallback_only":
    true` in the JSON (the key only then, so the output of every other policy is unchanged)."""
    if fallback is not None:
        click.echo(f"warning: {what} has no synthesized decision (0 rows): it is only its fallback, "
                   f"{fallback}; the values below are the fallback's", err=True)
        payload["fallback_only"] = True


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
