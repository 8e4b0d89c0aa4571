"""The dataset's codebook: for every column of every table of trustroute/core/dataset.py, its
unit, meaning and allowed values (docs/dataset.md says the same in prose). `codebook()` joins these
to the schemas' types and nullability; `trustroute export` writes it beside the tables, and
tests/core/test_codebook.py checks that every schema column has an entry and every entry a column.

An exported package holds no wall-clock time: each column of unit UTC is written as the seconds since
the participant's first recorded wall-clock time (EXPORTED_TIMES; `codebook(exported=True)` and
`exported_schema` describe the package's tables), so that the times keep each participant's
durations and order without the dates and times of day that would show the lab's schedule.
"""

from __future__ import annotations

import pyarrow as pa

from trustroute.core.dataset import TABLES
from trustroute.core.package import CONFIG_WITHOUT_PEOPLE_SEEDS as CONFIG_WITHOUT_PEOPLE_SEEDS
from trustroute.core.package import EXPORTED_TIMES as EXPORTED_TIMES
from trustroute.core.package import WITHOUT_PEOPLE_SEEDS as WITHOUT_PEOPLE_SEEDS
from trustroute.core.package import package_schema

UTC = "UTC"   # the unit of a wall-clock column (an ISO 8601 date-time)
TRUST = "integers 1-7 (1 = no trust, 7 = complete trust)"
PROBABILITIES = "list of probabilities summing to 1, one per trust level 1-7"
INCIDENTS = "obstacle, pedestrian, truck, none"
ID = "p<participant, 5 digits>-<spec>-<condition> (`p<..>-warmup` for a warm-up; pseudonymised in an export)"

# table -> column -> (unit, meaning, allowed values); "" where a unit does not apply
COLUMNS: dict[str, dict[str, tuple[str, str, str]]] = {
    "episodes": {
        "episode_id": ("", "the episode", ID),
        "participant": ("", "the participant (0-based; a pseudonym in an export)", "integers >= 0"),
        "position": ("", "the episode's place in the participant's planned order (Williams design; "
                         "an imported study: the order of its sessions)", "integers >= 0"),
        "spec": ("", "the route specification (spec file's stem)", "the study's specs"),
        "condition": ("", "the routing policy: trust-aware, trust-free or a policy file's stem",
                      "aware, free, or a policy name"),
        "seed": ("", "the simulator's seed of the episode",
                 "integers 0 .. 2^31-1; -1: none (an imported study, not run by trustroute)"),
        "satisfied": ("", "the episode ended with the specification accepted", "true, false"),
        "junctions": ("junctions", "junctions driven (roads after the start)", "integers >= 0"),
        "takeovers": ("roads", "roads with a takeover", "integers >= 0"),
        "final_trust": ("trust level", "true (simulated) or stated (live) trust at the end", TRUST),
        "mean_trust": ("trust level", "mean true or stated trust over the episode's roads", "1.0-7.0"),
        "end_reason": ("", "why the episode ended", "accepted, rejected, destination, cap"),
        "fallback_fired": ("", "the 20-junction rule took over from the policy at least once (never from "
                           "the trust-free policy, which already drives the rule's route)", "true, false"),
        "sim_seconds": ("s", "simulated time of the episode", ">= 0"),
        "wall_seconds": ("s", "wall-clock time of the episode", ">= 0"),
        "mean_reported_trust": ("trust level", "mean of the episode's trust reports", "1.0-7.0"),
        "reports": ("reports", "number of trust reports in the episode", "integers >= 0"),
        "driver_type": ("", "the simulated participant's true driver type", "the population's type names"),
        # the person's manual driving (live studies; null otherwise)
        "mean_takeover_reaction": ("s", "mean time from an incident coming into view to the takeover",
                                   ">= 0"),
        "mean_lateral_sd": ("m", "mean standard deviation of the lateral position while driving by wheel",
                            ">= 0"),
        "manual_min_ttc": ("s", "least time to collision while the person drove; inf: nothing closing in",
                           "> 0, inf"),
        "manual_max_deceleration": ("m/s^2", "largest deceleration while the person drove", ">= 0"),
        "oncoming_seconds": ("s", "time in the oncoming lane", ">= 0"),
        "road_departures": ("", "times the vehicle left the road while the person drove", "integers >= 0"),
        "collisions": ("", "collisions while the person drove", "integers >= 0"),
    },
    "roads": {
        "episode_id": ("", "the episode", ID),
        "index": ("", "the road's position in the episode; 0 = the start road", "integers >= 0"),
        "directed_road": ("", "the road U-V of the town (the vehicle arrives at junction V)",
                          "the town's roads"),
        "action": ("", "the junction the policy chose at the end of this road", "the town's junctions"),
        "incident": ("", "the road's incident", INCIDENTS),
        "takeover": ("", "the driver took over on this road", "true, false"),
        "performance": ("", "the automated vehicle's performance on this road", "succ, fail"),
        "trust_before": ("trust level", "true (simulated) or stated (live) trust entering the road", TRUST),
        "trust_after": ("trust level", "true or stated trust after the road", TRUST),
        "reported_trust": ("trust level", "the trust reported for this road (live: the answer to its "
                                          "prompt)", TRUST),
        "belief_before": ("probability", "the vehicle's belief over the trust levels before the road",
                          PROBABILITIES),
        "belief_after": ("probability", "the vehicle's belief after the road's observation", PROBABILITIES),
        "dfa_state": ("", "the specification automaton's state after the road",
                      "integers >= 0; -1: not tracked (an imported study: specs are evaluated by analysis)"),
        "fallback": ("", "the fallback (not the policy) chose `action`", "true, false"),
        "sim_time_in": ("s", "simulated time the vehicle entered the road", ">= 0"),
        "sim_time_out": ("s", "simulated time the vehicle entered the next road", ">= 0"),
    },
    "kinematics": {
        "episode_id": ("", "the episode", ID),
        "time": ("s", "simulated time of the step (steps of 0.5 s)", ">= 0"),
        "x": ("m", "vehicle front, east coordinate of the net", "real numbers"),
        "y": ("m", "vehicle front, north coordinate of the net", "real numbers"),
        "speed": ("m/s", "vehicle speed", ">= 0"),
        "lane": ("", "SUMO lane id the vehicle is on", "the net's lane ids"),
        "mode": ("", "who drives after this step", "auto, manual"),
    },
    "incidents": {
        "episode_id": ("", "the episode", ID),
        "index": ("", "the road's position in the episode", "integers >= 1"),
        "directed_road": ("", "the road U-V", "the town's roads"),
        "incident": ("", "the road's incident", INCIDENTS),
        "sumo_ids": ("", "comma-separated SUMO ids of the incident's objects", "text"),
        "injected_time": ("s", "when the objects were inserted", ">= 0"),
        "in_view_time": ("s", "when the objects came into view of the vehicle", ">= 0"),
        "x": ("m", "where the object was when it came into view (east)", "real numbers"),
        "y": ("m", "where the object was when it came into view (north)", "real numbers"),
        "passed_time": ("s", "when the vehicle passed the incident", ">= 0"),
        "removed_time": ("s", "when the last object was removed", ">= 0"),
        "takeover": ("", "the driver took over on this road", "true, false"),
        "takeover_start": ("s", "start of manual control", ">= 0"),
        "takeover_end": ("s", "end of manual control (the hand-back)", ">= 0"),
        "performance": ("", "the automated vehicle's performance on this road", "succ, fail"),
        "min_ttc": ("s", "minimum time to collision; inf when never within the threshold", "> 0, inf"),
        "max_deceleration": ("m/s^2", "strongest deceleration under autopilot", ">= 0"),
        "collided": ("", "the vehicle collided under autopilot", "true, false"),
        "min_head_on_ttc": ("s", "minimum head-on time to collision with an oncoming vehicle", "> 0, inf"),
        "min_pedestrian_distance": ("m", "closest distance to the incident's person on the crossing",
                                    ">= 0, inf"),
        "time_lost": ("s", "delay against free driving under autopilot", "real numbers"),
        "failed_measures": ("", "comma-separated measures beyond their limits",
                            "collision, deceleration, ttc, head_on_ttc, pedestrian_distance, time_lost"),
        "scene": ("", "the scene's drawn parameters and what happened (key=value pairs)", "text"),
        # the person's manual driving on this road (live studies; null otherwise)
        "takeover_reaction": ("s", "time from the incident coming into view to the takeover", ">= 0"),
        "lateral_sd": ("m", "standard deviation of the lateral position while driving by wheel", ">= 0"),
        "manual_min_ttc": ("s", "least time to collision while the person drove; inf: nothing closing in",
                           "> 0, inf"),
        "manual_max_deceleration": ("m/s^2", "largest deceleration while the person drove", ">= 0"),
        "oncoming_seconds": ("s", "time in the oncoming lane", ">= 0"),
        "road_departures": ("", "times the vehicle left the road while the person drove", "integers >= 0"),
        "collisions": ("", "collisions while the person drove", "integers >= 0"),
    },
    "attempts": {
        "participant": ("", "the participant (a pseudonym in an export)", "integers >= 0"),
        "episode_id": ("", "the drive attempted", ID),
        "warm_up": ("", "the attempt is of the warm-up drive", "true, false"),
        "planned_position": ("", "the drive's place in the planned order", "integers >= 0"),
        "attempt": ("", "the attempt's number for this drive", "integers >= 1"),
        "sequence": ("", "the attempt's number among the participant's attempts", "integers >= 1"),
        "run_position": ("", "a done trial's place in the order run", "integers >= 0"),
        "started_utc": (UTC, "when the attempt started", "ISO 8601 date-time"),
        "ended_utc": (UTC, "when the attempt ended", "ISO 8601 date-time"),
        "outcome": ("", "how the attempt ended", "started, aborted, failed, incomplete, done"),
        "reason": ("", "why it was aborted, failed or incomplete", "text"),
    },
    "questionnaires": {
        "participant": ("", "the participant (a pseudonym in an export)", "integers >= 0"),
        "episode_id": ("", "the trial the questionnaire followed (null: before the study or at its end)", ID),
        "placement": ("", "when it was asked", "before, after_each_trial, end"),
        "questionnaire": ("", "the questionnaire (jian: Jian et al. 2000; nasa_tlx: raw NASA-TLX; else a "
                              "study's own file)", "jian, nasa_tlx, or a file's name"),
        "item": ("", "the item's id", "the questionnaire's item ids"),
        "item_index": ("", "the item's place in the questionnaire", "integers >= 0"),
        "value": ("scale point", "the answer as given (reversed items not turned)", "scale_min .. scale_max"),
        "reversed": ("", "the item is scored reversed (scale_min + scale_max - value)", "true, false"),
        "scale_min": ("scale point", "the scale's lowest point", "real numbers"),
        "scale_max": ("scale point", "the scale's highest point", "real numbers"),
        "answered_utc": (UTC, "when the questionnaire was submitted", "ISO 8601 date-time"),
    },
}


SINCE_FIRST = ("in seconds since the participant's first recorded wall-clock time (the earliest start of "
               "their attempts or submission of their questionnaires, which is 0)")


# The ids of every table of an exported package, whose participants are pseudonyms (harness/study/
# export.py `pseudonyms`): a package's reader finds codes, not the study's 0-based numbers.
CODES = ("codes of one width drawn without replacement: 100-999 (more than 900 participants: 1000-9999; "
         "more than 9,000: 10000-99999, and so on)")
EXPORTED_IDS: dict[str, tuple[str | None, str]] = {   # column -> (meaning, None: the table's; allowed)
    "participant": ("the participant's pseudonym, a random code", CODES),
    "episode_id": (None, "p<participant code, 5 digits (code 114: p00114)>-<spec>-<condition> "
                         "(`p<..>-warmup` for a warm-up)"),
}


def exported_schema(table: str, people: bool = False) -> pa.Schema:
    """The schema of the table `table` (a key of TABLES) in an exported package (`package_schema`)."""
    return package_schema(TABLES[table][1], table, people)


def entry_of(table: str, column: str, exported: bool = False) -> tuple[str, str, str]:
    """(unit, meaning, allowed values) of a column of a study's or (`exported`) an exported package's
    table."""
    if exported and column in EXPORTED_IDS:
        unit, meaning, _ = COLUMNS[table][column]
        renamed, allowed = EXPORTED_IDS[column]
        return unit, renamed or meaning, allowed
    if column in COLUMNS[table]:
        return COLUMNS[table][column]
    (source,) = [utc for utc, seconds in EXPORTED_TIMES[table].items() if seconds == column]
    return "s", f"{COLUMNS[table][source][1]}, {SINCE_FIRST}", ">= 0"


def type_name(kind: pa.DataType) -> str:
    """The Arrow type's name (a list's without its item's field name, which Parquet renames)."""
    return f"list<{kind.value_type}>" if pa.types.is_list(kind) else str(kind)


def codebook(exported: bool = False, people: bool = False) -> dict[str, list[dict]]:
    """{table: [{column, type, nullable, unit, meaning, allowed}, ...]} in schema order: of a study's
    tables, or (`exported`) of an exported package's (`exported_schema`; `people`: a live study's)."""
    book: dict[str, list[dict]] = {}
    for table, (file_name, schema) in TABLES.items():
        fields = exported_schema(table, people) if exported else schema
        book[table] = [{"column": field.name, "file": file_name, "type": type_name(field.type),
                        "nullable": field.nullable, **dict(zip(("unit", "meaning", "allowed"),
                                                              entry_of(table, field.name, exported),
                                                              strict=True))}
                       for field in fields]
    return book
