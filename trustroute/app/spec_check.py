"""A spec checked as every command loads it: its DFA (translation time, sizes), the lint warnings
(policies/logic/lint.py) on the town and the driver model or population, and how many junctions
apart its waypoint sets lie; `trustroute spec check` prints it."""

from __future__ import annotations

import time

from trustroute.app.inputs import load_inputs
from trustroute.app.problem import compile_problem
from trustroute.core.errors import InputError
from trustroute.networks.road_lookup import waypoint_legs
from trustroute.policies.logic.dfa import DFATooLarge, dfa_from_formula
from trustroute.policies.logic.lint import lint


def spec_report(spec_path: str, town_path: str | None, population_path: str | None = None,
                driver_path: str | None = None) -> tuple[dict, str]:
    """(the JSON-ready summary of a spec check, the DFA as dot text). The spec is loaded as every
    command loads it: against the town and the driver model (`driver_path`, default the packaged
    model) or, with population_path, the driver population (type-belief atoms, the threshold check
    on its type-aware filter; docs/driver_types.md)."""
    inputs = load_inputs(spec_path, town_path, driver_path, population_path)
    town, spec, population = inputs.town, inputs.spec, inputs.population
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
    if population is not None:
        problem = compile_problem(inputs)   # lifted: a type the population lacks is one line, exit 2
        warnings = lint(problem.spec, town, dfa, problem.driver)
    else:
        warnings = lint(spec, town, dfa, inputs.model)
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
    waypoints = [(atom, spec.state_atoms[atom]) for atom in spec.formula_atoms if atom in spec.state_atoms]
    legs = waypoint_legs(town, spec.start, waypoints)
    return [{**leg.to_dict(), "roads": len(roads)} for leg, (_, roads) in zip(legs, waypoints, strict=True)]
