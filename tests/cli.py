"""Run the `trustroute` command in-process, as the tests of every package do."""

from __future__ import annotations

import pytest

from trustroute.harness.cli import main


def run_cli(capsys: pytest.CaptureFixture, *args: str) -> tuple[int, str, str]:
    """`trustroute ARGS`: (exit code, stdout, stderr). The CLI always ends with SystemExit."""
    with pytest.raises(SystemExit) as exit_info:
        main(list(args))
    captured = capsys.readouterr()
    return exit_info.value.code, captured.out, captured.err
