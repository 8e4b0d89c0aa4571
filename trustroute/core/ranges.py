"""The range of each numeric option, defined once: the API's settings and calls check a value with
its `OptionRange`, and the CLI's option of the same name parses its text and hands it to the same
check (harness/commands/options.py `Checked`), so the doors accept the same values and refuse the
others with the same words, the API's naming its keyword where the CLI's names its flag
(`keyword_names`). An option only the CLI has is checked by its range here too, so every refusal of
a number has the one wording. The numbers (the largest horizon, worker count, ...) are
trustroute/core/defaults.py's.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Generic, TypeVar

from trustroute.core import defaults
from trustroute.core.fields import Integer, Kind, Number, Seen, check_value, is_whole
from trustroute.core.wording import shown_value

T = TypeVar("T")

UNBOUNDED = Integer()   # an integer option without a largest value


@dataclass(frozen=True)
class OptionRange(Generic[T]):
    """The values one option takes at every door, and the fix its refusal names: the CLI's option
    type (harness/commands/options.py `Checked`) and the API's settings both check a value with
    `check`, so both doors refuse it with the same words (the API's naming its keyword,
    `keyword_names`)."""

    flag: str
    kind: Kind[T]
    fix: str   # its "{where}", if any, names where the value is written (`fix_at`)

    def check(self, value: object) -> T:
        """`value` when the option takes it, as the CLI parses it: a whole number (a numpy integer
        too) as an int, any real number of a number option (a numpy float or integer too) as a
        float; an InputError naming the flag otherwise. A bool is neither."""
        return self.check_as(value, self.flag)

    def check_as(self, value: object, source: str, place: str = "", where: str | None = None) -> T:
        """`check`, the refusal naming `source` and `place` instead of the flag and its fix `where`
        the value is written (`fix_at`; a settings object that names the option by its own keyword,
        SumoConfig's background_vehicles)."""
        if isinstance(self.kind, Number) and is_whole(value):   # a number option holds a float
            with contextlib.suppress(OverflowError):   # an int past every float is refused as it is
                value = float(value)
        fix = self.fix_at(where if where is not None else f"with {self.flag}")
        return check_value(value, self.kind, source, place, self.problem, fix)

    def fix_at(self, where: str) -> str:
        """The fix, in one wording at every door, its "{where}" naming where the value is written
        there: `with --background` on the command line, a config key, a settings object's keyword."""
        return self.fix.replace("{where}", where)

    def problem(self, seen: Seen) -> str:
        """What is wrong with a refused value: the kind's account, an integer's with the value as
        Python writes it (`'3'` is not 3) and without the bound it does not have."""
        kind = self.kind
        if isinstance(kind, Integer):
            # an option without a largest value still has the kind's: past it, the range is said whole
            beyond = is_whole(seen.value) and int(seen.value) > kind.maximum
            span = (f">= {kind.minimum}" if kind.maximum == UNBOUNDED.maximum and not beyond
                    else f"from {kind.minimum} to {kind.maximum}")
            return f"expected an integer {span}, got {shown_value(seen.value)}"
        rejection = kind.reject(seen.value)
        return rejection.problem if rejection is not None else ""


def _junctions(flag: str, example: str) -> OptionRange[int]:
    return OptionRange(flag, Integer(minimum=0, maximum=defaults.MAX_JUNCTIONS),
                       f"pass 0 to {defaults.MAX_JUNCTIONS} junctions, e.g. {example}")


def _positive(flag: str, unit: str, example: str) -> OptionRange[int]:
    return OptionRange(flag, Integer(minimum=1), f"pass a positive whole number of {unit}, e.g. {example}")


def _natural(flag: str, unit: str, example: str) -> OptionRange[int]:
    return OptionRange(flag, Integer(minimum=0), f"pass a whole number of {unit} >= 0, e.g. {example}")


# synthesis (`synthesize`, `trustroute synth`)
TAU = OptionRange("--tau", Number(minimum=0.0, maximum=1.0, open_below=True),
                  "pass a gap above 0, at most 1, e.g. --tau 1e-3")
HORIZON = OptionRange("--horizon", Integer(minimum=1, maximum=defaults.MAX_HORIZON),
                      f"pass 1 to {defaults.MAX_HORIZON} junctions, or omit --horizon (unbounded)")
TIME_LIMIT = OptionRange("--time-limit",
                         Number(minimum=0.0, maximum=defaults.MAX_TIME_LIMIT, open_below=True),
                         f"pass a number of seconds above 0, at most {defaults.MAX_TIME_LIMIT:g} (a week)")
WORK_LIMIT = _positive("--work-limit", "units", "--work-limit 20000000, or omit it")
NODE_BUDGET = _positive("--node-budget", "nodes", "--node-budget 2000000, or omit it")
# exact evaluation and episodes (`evaluate`, `run_episode`, `trustroute evaluate`, `trustroute run`)
FALLBACK_AFTER = _junctions("--fallback-after", str(defaults.FALLBACK_AFTER))
MAX_JUNCTIONS = _junctions("--max-junctions", str(defaults.JUNCTION_CAP))
MAX_NODES = _positive("--max-nodes", "histories per junction", "--max-nodes 5000")
SEED = OptionRange("--seed", Integer(minimum=0, maximum=defaults.MAX_SEED),
                   f"pass a whole number from 0 to {defaults.MAX_SEED}")
# the seed of a command's own draws, a numpy generator's (`fit`, `export`, `town import`): any
# non-negative integer, as a study config's seed
DRAW_SEED = _natural("--seed", "draws", "--seed 1")
INCIDENT_SEED = _natural("--incident-seed", "draws", "--incident-seed 1")
# background traffic (`trustroute run --background`; SumoConfig's and the study config's
# background_vehicles name it by their key, each refusal saying where it is written)
BACKGROUND_VEHICLES = OptionRange(
    "--background", Integer(minimum=0, maximum=defaults.MAX_BACKGROUND_VEHICLES),
    f"give a number of background vehicles from 0 to {defaults.MAX_BACKGROUND_VEHICLES} {{where}}, "
    "e.g. 20, or 0 for none")
BACKGROUND_KEY = "as background_vehicles in [study]"                # where a study config writes it
BACKGROUND_KEYWORD = "as SumoConfig(background_vehicles=...)"      # where the API's caller writes it
# studies (`run_study`, `trustroute study`)
WORKERS = OptionRange("--workers", Integer(minimum=1, maximum=defaults.MAX_WORKERS),
                      f"pass 1 (this process) to {defaults.MAX_WORKERS} processes, or omit --workers "
                      "(the CPU count)")
PARTICIPANTS = OptionRange("--participants", Integer(minimum=1, maximum=defaults.MAX_PARTICIPANTS),
                           f"pass 1 to {defaults.MAX_PARTICIPANTS} participants, e.g. --participants 21")
ATTEMPTS = OptionRange("--attempts", Integer(minimum=1, maximum=defaults.MAX_ATTEMPTS),
                       f"pass 1 to {defaults.MAX_ATTEMPTS} runs, e.g. --attempts {defaults.ATTEMPTS}")


def keep_checked(settings: object, accepted: Mapping[str, OptionRange],
                 optional: Collection[str] = ()) -> None:
    """Check each field of the frozen dataclass `settings` that `accepted` names by its range, and
    keep the value as checked (a numpy number as the int or float the CLI parses), so a settings
    object a script makes holds what the command's would; a field named in `optional` holding None
    (the option omitted) is left as it is."""
    for name, option in accepted.items():
        value = getattr(settings, name)
        if value is None and name in optional:
            continue
        object.__setattr__(settings, name, option.check(value))


def check_time_limit(seconds: object) -> float:
    """A time limit as every door takes it: a finite number of seconds above 0, at most a week; an
    InputError naming --time-limit otherwise (the API says `time_limit`)."""
    return float(TIME_LIMIT.check(seconds))


def study_workers(workers: int | None) -> int:
    """The worker processes of a study as every door takes them: `workers` checked, or (None) the
    CPU count, at most the largest count a door takes."""
    if workers is None:
        return min(os.cpu_count() or 1, defaults.MAX_WORKERS)
    return WORKERS.check(workers)


# planning (`trustroute plan`, trustroute/app/planning.py PlanSettings; its seed is SEED's range)
SIMULATIONS = OptionRange("--simulations", Integer(minimum=10, maximum=100_000),
                          "pass 10 to 100000 simulated studies per size, or omit --simulations")
ALPHA = OptionRange("--alpha", Number(minimum=0.0, maximum=0.5, open_below=True),
                    f"pass a level above 0, at most 0.5, e.g. --alpha {defaults.PLAN_ALPHA:g}")
TARGET = OptionRange("--target", Number(minimum=0.0, maximum=1.0, open_below=True),
                     f"pass a power above 0, at most 1, e.g. --target {defaults.PLAN_TARGET:g}")
PILOT_BOOTSTRAP = OptionRange("--pilot-bootstrap", Integer(minimum=0, maximum=10_000),
                              f"pass 0 to 10000 refits, e.g. --pilot-bootstrap {defaults.PILOT_BOOTSTRAP}")
# live studies (`trustroute live`, harness/live/server.py ServerOptions)
PACE = OptionRange("--pace", Number(minimum=0.0, maximum=10_000.0, open_below=True),
                   "pass simulated seconds per second above 0, at most 10000, e.g. --pace "
                   f"{defaults.LIVE_PACE:g}")
RESUME_WITHIN = OptionRange("--resume-within", Number(minimum=0.0, maximum=86_400.0, open_below=True),
                            "pass seconds above 0, at most 86400 (a day), e.g. --resume-within "
                            f"{defaults.LIVE_RESUME_WITHIN:g}")
# at least one browser's connections: the cap holds this machine's too, the console's browser included
CONNECTIONS_PER_ADDRESS = OptionRange(
    "--connections-per-address", Integer(minimum=defaults.LIVE_CONNECTIONS_PER_BROWSER, maximum=1_000_000),
    f"pass a count from {defaults.LIVE_CONNECTIONS_PER_BROWSER} (one browser's connections) to 1000000, "
    "e.g. --connections-per-address 256 where stations share one address (a NAT or a proxy on another host)")
# fitting (`trustroute fit`, analysis/fitting/driver_model.py fit_study)
ITERATIONS = OptionRange("--iterations", Integer(minimum=1, maximum=100_000),
                         f"pass 1 to 100000 iterations, e.g. --iterations {defaults.FIT_ITERATIONS}")
# fitting's bootstrap and driver types (`trustroute fit`); a sampled population's types
# (`trustroute population sample`)
BOOTSTRAP = OptionRange("--bootstrap", Integer(minimum=0, maximum=100_000),
                        "pass 0 (none) to 100000 resamples, e.g. --bootstrap 200")
_FIT_TYPES = Integer(minimum=1, maximum=20)
TYPES = OptionRange("--types", _FIT_TYPES, f"pass 1 to {_FIT_TYPES.maximum} driver types, or auto")
MAX_TYPES = OptionRange("--max-types", _FIT_TYPES, f"pass 1 to {_FIT_TYPES.maximum} driver types, e.g. "
                        f"--max-types {defaults.FIT_MAX_TYPES}")
RESTARTS = OptionRange("--restarts", Integer(minimum=1, maximum=1_000),
                       f"pass 1 to 1000 restarts, e.g. --restarts {defaults.FIT_RESTARTS}")
SAMPLED_TYPES = OptionRange("--types", Integer(minimum=1, maximum=1_000),
                            "pass 1 to 1000 driver types, e.g. --types 3")
CONCENTRATION = OptionRange("--concentration", Number(minimum=0.0, open_below=True),
                            "pass a finite concentration above 0, e.g. --concentration 50")
TAKEOVER_SPREAD = OptionRange("--takeover-spread", Number(minimum=0.0),
                              "pass a finite sd >= 0, e.g. --takeover-spread 0.5")
# live studies' socket (`trustroute live`)
PORT = OptionRange("--port", Integer(minimum=0, maximum=65_535),
                   "pass a port from 0 (any free one) to 65535, e.g. --port 8765")
# a town's roads near a point (`trustroute town roads --near X Y`; --limit)
COORDINATE = OptionRange("--near", Number(),
                         "pass two finite numbers in the town's metres, e.g. --near 120 -45")
ROAD_LIMIT = _positive("--limit", "roads", "--limit 10")
# peers (`trustroute peer storm|paynt`): their limits and our search's (their --horizon is HORIZON:
# the same step bound, and its product is bounded by defaults.MAX_PEER_PRODUCT)
DEPTH = _natural("--depth", "junctions", "--depth 10")
PEER_MAX_NODES = _positive("--max-nodes", "belief nodes per level", "--max-nodes 200000")
PEER_TIME_LIMIT = OptionRange("--time-limit", Number(minimum=1.0),
                              "pass a finite number of seconds >= 1, e.g. --time-limit 30")
# our search's seconds: any a synthesis takes (TIME_LIMIT's), or omitted for none
OUR_TIME_LIMIT = OptionRange("--our-time-limit", TIME_LIMIT.kind,
                             f"{TIME_LIMIT.fix}, or omit --our-time-limit (no limit)")
RESOLUTION = _positive("--resolution", "steps", "--resolution 2")
MAX_STATES = _positive("--max-states", "states", "--max-states 200000")
