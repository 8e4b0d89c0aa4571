"""`trustroute run`: one episode in SUMO with a synthetic driver; logs to Parquet, optional Rerun."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import click

from trustroute.app.problem import load_problem
from trustroute.core import defaults, ranges
from trustroute.core.wording import counted
from trustroute.harness.commands.inputs import POPULATION_GIVEN, driver_field, spec_argument, town_field
from trustroute.harness.commands.option_groups import option, takes
from trustroute.harness.commands.options import SEED, Checked, UsageFix
from trustroute.harness.commands.output import json_flag, quiet_flag, with_paths

if TYPE_CHECKING:
    from collections.abc import Callable

    from trustroute.app.runs import EpisodeSettings
    from trustroute.harness.simulation.sumo_start import SumoConfig


def _write_logs(out_dir: Path, record) -> dict[str, Path]:
    """Each log file written atomically (a full disk leaves the old file or none, never half)."""
    from trustroute.core.dataset import (
        INCIDENTS_FILE,
        INCIDENTS_SCHEMA,
        KINEMATICS_FILE,
        KINEMATICS_SCHEMA,
        ROADS_FILE,
        ROADS_SCHEMA,
        SUMMARY_FILE,
        table_from_frame,
        write_table,
    )
    from trustroute.core.output_files import atomic_write_text

    written = {}
    for name, frame, file_name, schema in (
            ("roads", record.roads, ROADS_FILE, ROADS_SCHEMA),
            ("kinematics", record.kinematics, KINEMATICS_FILE, KINEMATICS_SCHEMA),
            ("incidents", record.incidents, INCIDENTS_FILE, INCIDENTS_SCHEMA)):
        written[name] = write_table(table_from_frame(frame, schema), out_dir / file_name)
    written["summary"] = out_dir / SUMMARY_FILE
    atomic_write_text(written["summary"], json.dumps(record.summary, indent=1) + "\n",
                      "episode summary", "pass a writable directory with --out")
    return written


def routes_file(path: str) -> str:
    """A background route file (a path, or a packaged name: `city`, the city's own demand), read once
    to fail early with one line (absolute: SUMO resolves it)."""
    from trustroute.app.towns import route_file

    return route_file(path)


def _spec_path(spec_argument: str | None, spec_option: str | None) -> str:
    """The spec file, given once: as the SPEC argument or by its old spelling --spec."""
    if spec_argument is not None and spec_option is not None:
        raise UsageFix("the spec is given twice",
                       "give it once, as the SPEC argument (--spec is its old spelling)")
    spec_path = spec_argument if spec_argument is not None else spec_option
    if spec_path is None:
        raise UsageFix("missing argument SPEC", "pass a spec file or a packaged spec name, e.g. "
                       "`trustroute run phi1`")
    return spec_path


def _check_paths(options: RunOptions, spec_path: str) -> None:
    """Every output is writable, the recording overwrites no input, and the given net is readable,
    before SUMO starts."""
    from trustroute.app.synthesis import policy_arrays
    from trustroute.core.output_files import check_output_dir, check_output_file

    out_dir, rrd_path, net_path = options.out_dir, options.rrd_path, options.net_path
    if out_dir is not None:
        check_output_dir(out_dir, "--out", "log directory")
    if rrd_path is not None:
        policy = options.policy_name   # a file, or a name such as aware
        reads = {"SPEC": spec_path, "--policy": policy,
                 "--policy's .npz": policy_arrays(policy) if Path(policy).is_file() else None,
                 "--town": options.town_path,
                 "--driver": options.driver_path, "--net": net_path, "--population": options.population_path,
                 **{f"--routes #{number}": path for number, path in enumerate(options.routes_paths, 1)}}
        check_output_file(rrd_path, "--rrd", "Rerun recording", reads, suffix=".rrd")
    if options.cache_dir is not None:
        check_output_dir(options.cache_dir, "--cache-dir", "policy cache")
    if net_path is not None:
        from trustroute.core.validation import read_input_bytes

        read_input_bytes(net_path, "SUMO net", max_bytes=1 << 30, fix="pass a .net.xml written by "
                         "`trustroute net build`")


@dataclass(frozen=True)
class RunOptions:
    """`trustroute run`'s options, in the order --help lists them."""

    spec_option: str | None = option("--spec", type=click.Path(), default=None, hidden=True,
                                      help="Deprecated spelling of the SPEC argument.")
    policy_name: str = option("--policy", default=defaults.POLICY, show_default=True,
                              help="'aware', 'free' or a policy file.")
    seed: int = option("--seed", type=SEED, default=defaults.SEED, show_default=True,
                       help="SUMO seed and driver seed.")
    rrd_path: str | None = option("--rrd", type=click.Path(), default=None,
                                  help="Rerun recording FILE to write.")
    out_dir: str | None = option(
        "--out", type=click.Path(), default=None,
        help="DIRECTORY to write roads/kinematics/incidents Parquet and summary.json into.")
    as_json: bool = json_flag()
    town_path: str | None = town_field()
    driver_path: str | None = driver_field()
    net_path: str | None = option(
        "--net", type=click.Path(), default=None,
        help="SUMO net to use (default: the net the town drives: an imported town's own, "
             "else its cached built net, built if missing).")
    initial_trust: int | None = option("--initial-trust", type=int, default=None,
                                       help="Driver's initial trust (default: drawn).")
    population_path: str | None = option(
        "--population", type=click.Path(), default=None,
        help=f"{POPULATION_GIVEN} (instead of --driver): the driver's type is drawn from it "
             "(seeded), the AV filters with its type-aware model; POLICY 'free', 'robust', "
             "'bayes' or a population policy file (docs/driver_types.md).")
    cache_dir: str | None = option("--cache-dir", type=click.Path(), default=None,
                                   help="Where 'aware' policies are cached.")
    sumo_dir: str | None = option(
        "--sumo-files", type=click.Path(), default=None,
        help="DIRECTORY to write episode.sumocfg, the net, SUMO's route and FCD outputs into "
             "(open with sumo-gui).")
    routes_paths: tuple[str, ...] = option(
        "--routes", type=click.Path(), multiple=True,
        help="SUMO route FILE of background traffic, e.g. an imported scenario's vehicle types and "
             "demand (repeat for several; types first); 'city': the demand of --town city.")
    background_vehicles: int = option(
        "--background", type=Checked(ranges.BACKGROUND_VEHICLES), default=0,
        show_default=True,
        help="Seeded background traffic: vehicles kept on the net (an imported "
             "town: trips per minute from SUMO's randomTrips.py); docs/scenes.md.")
    quiet: bool = quiet_flag()

    def sumo_config(self) -> SumoConfig:
        """SUMO's options: the background traffic, and with --sumo-files the folder of its files."""
        from trustroute.harness.simulation.sumo_files import prepare_directory
        from trustroute.harness.simulation.sumo_start import SumoConfig

        config = SumoConfig(background_vehicles=self.background_vehicles,
                            route_files=tuple(routes_file(path) for path in self.routes_paths))
        if self.sumo_dir is None:
            return config
        return replace(config, output_dir=str(prepare_directory(Path(self.sumo_dir)).resolve()))

    def episode(self, sumo: SumoConfig, observer: Callable | None) -> EpisodeSettings:
        """The episode's settings: the seed, the initial trust, the Rerun file, the net, SUMO's."""
        from trustroute.app.runs import EpisodeSettings

        return EpisodeSettings(seed=self.seed, initial_trust=self.initial_trust,
                               rrd=Path(self.rrd_path) if self.rrd_path else None,
                               net=Path(self.net_path) if self.net_path else None, sumo=sumo,
                               observer=observer)


@click.command("run")
@spec_argument("spec_argument", required=False, type=click.Path())
@takes(options=RunOptions)
def run(spec_argument: str | None, options: RunOptions) -> None:
    """Run one episode of SPEC in SUMO with POLICY and a synthetic driver.

    To re-run an episode of a study exactly (its participant's drawn model and initial trust), use
    `trustroute replay STUDY_DIR EPISODE_ID`.
    """
    from trustroute.app.policy import PolicySettings, policy_for
    from trustroute.app.runs import run_one_episode
    from trustroute.app.towns import check_routes_town
    from trustroute.harness.simulation.sumo_files import VehicleTypeCollector, write_episode_files

    as_json, seed, sumo_dir, rrd_path = options.as_json, options.seed, options.sumo_dir, options.rrd_path
    spec_path = _spec_path(spec_argument, options.spec_option)
    _check_paths(options, spec_path)
    problem = load_problem(spec_path, options.town_path, options.driver_path, options.population_path)
    check_routes_town(options.routes_paths, problem.town)
    policy = policy_for(problem, options.policy_name, PolicySettings(cache_dir=options.cache_dir,
                                                                     progress=not (as_json or options.quiet)))
    sumo_config = options.sumo_config()
    types = VehicleTypeCollector() if sumo_dir is not None else None
    ran = run_one_episode(problem, policy, options.episode(sumo_config, types))
    record, episode_id, driver_type, net = ran.record, ran.episode_id, ran.driver_type, ran.net
    written = _write_logs(Path(options.out_dir), record) if options.out_dir else {}
    if rrd_path:
        written["rrd"] = Path(rrd_path)
    if sumo_dir is not None and types is not None and net is not None:  # (SUMO: the net is known)
        written.update(write_episode_files(Path(sumo_dir), types.types, net, seed, sumo_config))
    summary = dict(record.summary)
    summary["route"] = record.roads["directed_road"].tolist()
    if driver_type is not None:
        summary["driver_type"] = driver_type
    if as_json:
        click.echo(json.dumps(with_paths(summary, written)))
        return
    click.echo(f"{episode_id}: {summary['end_reason']} after {counted(summary['junctions'], 'junction')}, "
               f"satisfied={summary['satisfied']}, takeovers={summary['takeovers']}, final trust "
               f"{summary['final_trust']}, sim {summary['sim_seconds']:.1f} s, wall "
               f"{summary['wall_seconds']:.2f} s")
    click.echo("route: " + " ".join(summary["route"]))
    if driver_type is not None:
        click.echo(f"driver type (drawn from the population): {driver_type}")
    for path in written.values():
        click.echo(f"wrote {path}")
