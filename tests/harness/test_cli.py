"""The CLI's last nets: an OSError no command foresaw is one line whose fix follows the errno; a
Ctrl-C, or a SIGTERM, is one line saying what the interrupted command left behind."""

from __future__ import annotations

import errno
import signal
import subprocess
import sys
from pathlib import Path

import click
import pytest

from tests.cli import assert_one_line_error, run_cli
from trustroute.harness import cli

REPO = Path(__file__).resolve().parents[2]
RAW = REPO / "analysis" / "data" / "real_study" / "raw"


def test_an_output_directory_that_is_a_file_is_named_in_the_fix(tmp_path, monkeypatch, capsys):
    """A folder made under a file (the file system's own ENOTDIR, unforeseen by the command): the fix
    names the file in the way, not the folder, and says nothing of disk space."""
    blocker = tmp_path / "afile"
    blocker.write_text("a file, not a folder\n")

    @click.command("mkdir")
    def make_folder() -> None:
        (blocker / "sub").mkdir()

    monkeypatch.setattr(cli.LazyGroup, "get_command", lambda self, ctx, name: make_folder)
    code, _, err = run_cli(capsys, "mkdir")
    assert_one_line_error(code, err, str(blocker / "sub"), f"{blocker} must be a directory, not a file")
    assert "disk space" not in err
    assert blocker.read_text() == "a file, not a folder\n"


def test_import_carla_logs_refuses_an_out_that_is_a_file(tmp_path, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("a file, not a folder\n")
    code, _, err = run_cli(capsys, "import", "carla-logs", str(RAW), "--out", str(blocker))
    assert_one_line_error(code, err, str(blocker), "not a directory")
    assert blocker.read_text() == "a file, not a folder\n"


@pytest.mark.parametrize(("code", "fix"), [(errno.ENOSPC, "free disk space, then rerun"),
                                           (errno.EACCES, "fix the permissions of /x/y"),
                                           (errno.EIO, "check that /x/y can be read and written")])
def test_an_unforeseen_os_error_gets_the_fix_of_its_errno(code, fix, monkeypatch, capsys):
    @click.command("boom")
    def boom() -> None:
        raise OSError(code, "failed", "/x/y")

    monkeypatch.setattr(cli.LazyGroup, "get_command", lambda self, ctx, name: boom)
    exit_code, _, err = run_cli(capsys, "boom")
    assert_one_line_error(exit_code, err, "/x/y", fix)


@click.command()
def ctrl_c() -> None:
    """A command the user interrupts at once (Ctrl-C)."""
    raise KeyboardInterrupt


@pytest.mark.parametrize("command, says", [
    ("study", "the same command resumes it"),
    ("demo", "the same command resumes it"),
    ("live", "the same command serves it again"),
    ("synth", "no file was left half-written"),
    ("fit", "no file was left half-written"),
    ("plan", "no file was left half-written"),
    ("export", "the package directory is incomplete: delete it"),
    ("analyze", None),   # its report's files are written in place: nothing is claimed of them
])
def test_an_interrupted_command_says_in_one_line_what_it_left(command, says, monkeypatch, capsys):
    monkeypatch.setitem(cli.COMMANDS, command, (__name__, "ctrl_c", "stands in for the command"))
    code, out, err = run_cli(capsys, command)
    assert code == 130 and out == ""
    assert err.count("\n") == 1 and err.endswith("\n"), err   # one line: no blank one before it
    line = err.rstrip("\n")
    if says is None:
        assert line == "interrupted", err
    else:
        assert line.startswith("interrupted (") and line.endswith(")") and says in line, err


@pytest.mark.slow
def test_sigterm_ends_a_command_as_ctrl_c_does(tmp_path):
    """A real SIGTERM to `trustroute synth` (a synthesis of about 30 s): the one interrupted line,
    exit 130, no traceback, and no file left behind, half-written or whole."""
    process = subprocess.Popen(
        [sys.executable, "-m", "trustroute", "synth", "city5", "--tau", "1e-9", "--time-limit", "60",
         "--out", str(tmp_path / "policy.json")],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # its first progress line (after 2 s): the synthesis runs
        assert process.stderr.readline().startswith("synthesizing city5"), process.stderr.read()
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 130 and "Traceback" not in err, err
    assert err.splitlines()[-1] == cli.interrupted_line("synth"), err
    assert out == "" and list(tmp_path.iterdir()) == []
