"""A command's options as dataclasses (harness/commands/option_groups.py): each field is one
option, added in field order, and the command receives the objects built from what click parsed;
an option not given is the field's default."""

from __future__ import annotations

from dataclasses import dataclass, fields

import click
import pytest
from click.testing import CliRunner

from trustroute.harness.commands import fit, live, peer, plan, run, study, synth
from trustroute.harness.commands.option_groups import option, takes


@dataclass(frozen=True)
class Search:
    depth: int = option("--depth", type=int, default=3, show_default=True, help="Depth.")
    names: tuple[str, ...] = option("--name", multiple=True, help="Repeatable.")


@dataclass(frozen=True)
class Output:
    as_json: bool = option("--json", is_flag=True, help="JSON.")
    warm: bool = option("--warm/--cold", default=True, help="Warm.")


@click.command("toy")
@click.argument("spec")
@takes(search=Search, output=Output)
def toy(spec: str, search: Search, output: Output) -> None:
    """A toy command."""
    click.echo(repr((spec, search, output)))


def test_the_options_are_the_fields_in_order_and_the_command_gets_the_objects():
    assert [p.name for p in toy.params] == ["spec", "depth", "names", "as_json", "warm"]
    assert [p.opts for p in toy.params[1:]] == [["--depth"], ["--name"], ["--json"], ["--warm"]]
    done = CliRunner().invoke(toy, ["phi1", "--depth", "5", "--name", "a", "--name", "b", "--cold"])
    assert done.exit_code == 0, done.output
    assert done.output.strip() == repr(("phi1", Search(depth=5, names=("a", "b")), Output(warm=False)))
    omitted = CliRunner().invoke(toy, ["phi1"])
    assert omitted.output.strip() == repr(("phi1", Search(), Output()))
    assert toy.help == "A toy command."


def test_a_bad_value_is_still_clicks_usage_error():
    done = CliRunner().invoke(toy, ["phi1", "--depth", "x"])
    assert done.exit_code == 2 and "'x' is not a valid integer" in done.output


@pytest.mark.parametrize(("command", "arguments", "groups"), [
    (synth.synth, ["phi1"], [synth.SynthOptions]),
    (synth.evaluate, ["phi1", "free"], [synth.EvaluateOptions]),
    (run.run, ["phi1"], [run.RunOptions]),
    (study.study, ["c.toml"], [study.StudyOptions]),
    (live.live, ["c.toml"], [live.ServeOptions]),
    (plan.plan, ["c.toml"], [plan.PlanOptions]),
    (fit.fit, ["dir"], [fit.FitOptions]),
    (peer.storm, ["phi1"], [peer.PeerProblem, peer.StormLimits, peer.OurSide]),
    (peer.paynt, ["phi1"], [peer.PeerProblem, peer.PayntLimits, peer.OurSide]),
])
def test_each_commands_omitted_options_are_its_groups_defaults(command, arguments, groups):
    """What click gives for an option not passed is the field's default: one default per option."""
    context = command.make_context(command.name, list(arguments))
    for group in groups:
        assert group(**{f.name: context.params[f.name] for f in fields(group)}) == group()
