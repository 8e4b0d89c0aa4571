"""The `trustroute` command: one click group; each subcommand lives in harness/commands/.

Subcommand modules are imported only when their command runs, so `trustroute --help`
stays fast and a broken optional dependency cannot stop unrelated commands.
Bad input (InputError) becomes one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import importlib
import sys
import time

import click

from trustroute.core.errors import InputError
from trustroute.core.interrupts import sigterm_raises
from trustroute.harness.commands.options import CommandStart, UsageFix

# name -> (module, attribute, one-line help)
COMMANDS: dict[str, tuple[str, str, str]] = {
    "net": ("trustroute.harness.commands.net", "net", "Build and inspect the SUMO network of a town."),
    "spec": ("trustroute.harness.commands.spec", "spec", "Check scLDTL spec files."),
    "synth": ("trustroute.harness.commands.synth", "synth", "Synthesize a trust-aware policy with bounds."),
    "baseline": ("trustroute.harness.commands.synth", "baseline", "The trust-free shortest baseline route."),
    "evaluate": ("trustroute.harness.commands.synth", "evaluate", "Exact satisfaction probability."),
    "run": ("trustroute.harness.commands.run", "run", "Run one episode in SUMO."),
    "replay": ("trustroute.harness.commands.replay", "replay",
               "Re-run one study episode exactly, check it, and record it for Rerun."),
    "study": ("trustroute.harness.commands.study", "study", "Run a simulated within-subject study."),
    "live": ("trustroute.harness.commands.live", "live", "Serve a study to people in their browsers."),
    "analyze": ("trustroute.harness.commands.analyze", "analyze", "Analyse a study directory."),
    "export": ("trustroute.harness.commands.export", "export",
               "Package a study for sharing: pseudonymous tables, codebook, checksums."),
    "withdraw": ("trustroute.harness.commands.withdraw", "withdraw",
                 "Delete a live study participant's data (withdrawal), audited."),
    "plan": ("trustroute.harness.commands.plan", "plan", "Power and sample size of a study, by simulation."),
    "fit": ("trustroute.harness.commands.fit", "fit", "Fit a driver model to a study's logs."),
    "population": ("trustroute.harness.commands.population", "population",
                   "Sample and inspect driver populations (driver types)."),
    "import": ("trustroute.harness.commands.importing", "import_group", "Import logs of real studies."),
    "demo": ("trustroute.harness.commands.demo", "demo", "Run the paper-size study (21 drivers) and report."),
    "model": ("trustroute.harness.commands.model", "model", "Summarise the trust POMDP of a town and model."),
    "peer": ("trustroute.harness.commands.peer", "peer", "Independent solvers (Storm, PAYNT) beside ours."),
    "town": ("trustroute.harness.commands.town", "town", "Import SUMO nets and OpenStreetMap maps as towns."),
}


class Interrupted(Exception):
    """Ctrl-C or SIGTERM ended `command` (None: before a command was chosen)."""

    def __init__(self, command: str | None) -> None:
        super().__init__(command)
        self.command = command


class LazyGroup(click.Group):
    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module_name, attribute, _ = COMMANDS[name]
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                return None
            raise
        return getattr(module, attribute)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][2]) for name in sorted(COMMANDS)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> object:
        # Ctrl-C, and SIGTERM (`main` turns it into a KeyboardInterrupt), leave the command here as
        # `Interrupted`, naming it, before click's `main` sees it: click would print a blank line
        # and raise a bare Abort, which names no command.
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as exc:
            raise Interrupted(ctx.invoked_subcommand) from exc


@click.group(cls=LazyGroup)
@click.version_option(package_name="trustroute")
def cli() -> None:
    """trustroute: trust-aware routing of an autonomous vehicle, studied on SUMO."""


def usage_fix(exc: click.UsageError, command: str) -> str:
    """The fix of a usage error: the option click suggests, the missing argument to pass, or the
    values a parameter takes."""
    if isinstance(exc, UsageFix):
        return exc.fix
    if isinstance(exc, click.NoSuchOption):
        if exc.possibilities:
            return f"use {' or '.join(sorted(exc.possibilities))}"
        return f"use an option `{command} --help` lists"
    param, ctx = (exc.param if isinstance(exc, click.BadParameter) else None), exc.ctx
    if param is not None and ctx is not None:
        hint = param.get_error_hint(ctx)
        if isinstance(exc, click.MissingParameter):
            return f"pass {hint} (`{command} --help` says what it takes)"
        if isinstance(param.type, click.Choice):
            return f"pass {hint} as one of {', '.join(map(str, param.type.choices))}"
        return f"pass {hint} as {param.type.name} (`{command} --help` gives its range)"
    if isinstance(exc, click.BadArgumentUsage) or "unexpected extra argument" in str(exc):
        return f"drop it; `{command} --help` lists the arguments"
    if exc.ctx is None or exc.ctx.parent is None:   # the group itself: a command name was wrong
        return f"pick one of the commands: {', '.join(sorted(COMMANDS))}"
    return f"follow the usage `{command} --help` prints"


# What an interrupted command leaves behind, said only where it holds: a study (and the demo's)
# keeps every finished episode's part (harness/study/runner.py) and a live study its registry and
# parts (harness/live/session.py); synth, fit and plan write each file atomically
# (trustroute/core/output_files.py); export fills a package directory it then refuses as not empty.
_RESUMED = "what it wrote stays: the same command resumes it, running only the episodes not yet finished"
_WHOLE_FILES = "no file was left half-written: each is whole or not written; run the command again"
INTERRUPTED_NOTES: dict[str, str] = {
    "study": _RESUMED,
    "demo": _RESUMED,
    "live": ("what the study wrote stays: the same command serves it again, each participant "
             "continuing at their unfinished trial"),
    "synth": _WHOLE_FILES,
    "fit": _WHOLE_FILES,
    "plan": _WHOLE_FILES,
    "export": "the package directory is incomplete: delete it, then run the command again",
}


def interrupted_line(command: str | None) -> str:
    """The one line an interrupted `command` ends with: what it left behind, where that is known."""
    note = INTERRUPTED_NOTES.get(command or "")
    return "interrupted" if note is None else f"interrupted ({note})"


def _echo_interrupted(command: str | None) -> None:
    # On a terminal the ^C the terminal echoed has no newline: the line starts on its own row.
    lead = "\n" if sys.stderr.isatty() else ""
    click.echo(lead + interrupted_line(command), err=True)


def main(argv: list[str] | None = None) -> None:
    # when the command began, which a --time-limit counts from (harness/commands/options.py): the
    # process's start when the process is the command (no argv given: the console script, python -m
    # trustroute), else now (a caller running it in-process)
    started = CommandStart.now() if argv is None else CommandStart(time.perf_counter())
    try:
        # SIGTERM ends every command as Ctrl-C does: its clean-up runs, then the one interrupted line
        with sigterm_raises():
            code = cli.main(args=argv, prog_name="trustroute", standalone_mode=False, obj=started)
    except InputError as exc:
        click.echo(f"error: {exc.one_line()}", err=True)
        sys.exit(2)
    except Interrupted as exc:
        _echo_interrupted(exc.command)
        sys.exit(130)
    except click.exceptions.Abort as exc:
        # click turns a Ctrl-C while it parses the command line (before `LazyGroup.invoke`) into Abort
        if isinstance(exc.__context__, KeyboardInterrupt):
            _echo_interrupted(None)
        else:
            click.echo("aborted", err=True)
        sys.exit(130)
    except click.UsageError as exc:
        # One line naming the fix, like every other error (click would print the usage, a hint and
        # a blank line first).
        command = exc.ctx.command_path if exc.ctx is not None else "trustroute"
        message = " ".join(exc.format_message().split())
        error = InputError(command, "", message, usage_fix(exc, command))
        click.echo(f"error: {error.one_line()}", err=True)
        sys.exit(2)
    except click.ClickException as exc:
        click.echo(f"error: {' '.join(exc.format_message().split())}", err=True)
        sys.exit(2 if exc.exit_code == 2 else exc.exit_code)
    except KeyboardInterrupt:
        _echo_interrupted(None)
        sys.exit(130)
    except OSError as exc:
        # The last net under every command: an I/O failure no command foresaw (a disk that filled
        # up, a folder that became read-only) is still one line, not a traceback.
        from trustroute.core.output_files import os_error_fix, os_error_text

        where = exc.filename if exc.filename is not None else "trustroute"
        error = InputError(str(where), "", os_error_text(exc), os_error_fix(exc))
        click.echo(f"error: {error.one_line()}", err=True)
        sys.exit(2)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
